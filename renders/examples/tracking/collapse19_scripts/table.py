"""Dev table: within / over / score per set for main and candidates (a candidate's missing set = main's, by the
RULE's shortcut: marked *)."""
import json, sys
from pathlib import Path
R = Path('/work/collapse19/out')
sets = sys.argv[2].split(',')
tags = sys.argv[1].split(',')
def get(tag, s):
    p = R / tag / f'{s}.json'
    if p.exists():
        o = json.loads(p.read_text()); return o['all']['within'], o['all']['over'], o['accepted_pct'], False
    o = json.loads((R / 'main' / f'{s}.json').read_text()); return o['all']['within'], o['all']['over'], o['accepted_pct'], True
tot = {t: [0, 0] for t in tags}
worst = {t: [] for t in tags}
print('| set | ' + ' | '.join(tags) + ' |'); print('|---' * (len(tags) + 1) + '|')
for s in sets:
    cells = []
    mw, mo, _, _ = get('main', s)
    for t in tags:
        w, o, a, copied = get(t, s)
        tot[t][0] += w; tot[t][1] += o
        if o - mo > 5: worst[t].append(f'{s} +{o - mo}')
        cells.append(f'{a:.1f} % / {w} / {o}' + (' *' if copied and t != 'main' else ''))
    print(f'| {s} | ' + ' | '.join(cells) + ' |')
print('| **within / over, score** | ' + ' | '.join(f'{w} / {o}, **{w - 10 * o}**' for w, o in tot.values()) + ' |')
print('| over 3 px up > 5 | ' + ' | '.join(', '.join(worst[t]) or 'none' for t in tags) + ' |')
