import json, sys
for p in sys.argv[1:]:
    d = json.load(open(p)); g = d['suites']['generate'] if 'suites' in d else d['generate']
    h = g['hard_layer_over_base_one_thread']; hh = g['hard_over_base_one_thread']
    print(p.split('/')[-1], "hard_layer/base1", round(h['ratio'], 3), [round(v, 3) for v in h['ratio_spread']['rounds']], "wall", round(h['wall_ratio'], 3),
          "| hard/base1", round(hh['ratio'], 3), "| load", g['hard_over_base']['load_average'])
