"""usage: python table.py TAG [TAG...] [--sets a,b,...]: per set within / over / score and mirror lost, vs the first tag."""
import json, sys
from pathlib import Path
args = sys.argv[1:]
sets = None
if "--sets" in args:
    i = args.index("--sets"); sets = args[i + 1].split(","); args = args[:i] + args[i + 2:]
tags = args
sets = sets or "hard_s47 hard_s48 hard_s49 hard_s50 hard_s51 hard_s52 hard_s53 hard_s54 hard_s55 hard_s57 default_s8".split()
tot = {t: [0, 0, 0, 0, 0] for t in tags}
print("| set | " + " | ".join(f"{t} within / over / score (mirror acc/vis)" for t in tags) + " |")
print("|---|" + "---|" * len(tags))
for s in sets:
    cells = []
    for t in tags:
        p = Path(f"/work/hard18/out/{t}/{s}.json")
        if not p.exists():
            cells.append("-"); continue
        o = json.loads(p.read_text())
        w, ov = o["all"]["within"], o["all"]["over"]
        m = o["virtual"]
        tot[t][0] += w; tot[t][1] += ov; tot[t][2] += m["accepted"]; tot[t][3] += m["visible"]; tot[t][4] += o["cpu_ms_per_frame"]
        cells.append(f"{w} / {ov} / {w - 10 * ov} ({m['accepted']}/{m['visible']})")
    print(f"| {s} | " + " | ".join(cells) + " |")
print("| total | " + " | ".join(f"{a} / {b} / {a - 10 * b} ({c}/{d}); cpu {e:.0f}" for a, b, c, d, e in tot.values()) + " |")
