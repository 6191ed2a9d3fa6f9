import json, sys
from pathlib import Path
R = Path("/work/corner19/out")
tags = sys.argv[1:]
sets = sorted(p.stem for p in (R / "main").glob("*.json"))
tot = {t: 0 for t in tags}
print("set        " + "".join(f"{t:>24s}" for t in tags))
for s in sets:
    row, base = f"{s:10s} ", None
    for t in tags:
        p = R / t / f"{s}.json"
        if not p.exists():
            row += f"{'-':>24s}"; continue
        a = json.loads(p.read_text())["all"]
        sc = a["within"] - 10 * a["over"]
        base = sc if base is None else base
        tot[t] += sc
        row += f"{a['within']:6d}/{a['over']:4d} {sc:6d} ({sc-base:+5d})"
    print(row)
print("total      " + "".join(f"{tot[t]:24d}" for t in tags))
