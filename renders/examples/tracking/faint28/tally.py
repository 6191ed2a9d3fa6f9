"""faint28: totals per variant and preset over the sets both variants have, and per-set differences.
usage: tally.py ROWS.jsonl..."""
import json
import sys
from collections import defaultdict

rows = defaultdict(dict)
for path in sys.argv[1:]:
    for line in open(path):
        r = json.loads(line)
        rows[r["set"]][r["variant"]] = r
sets = sorted(s for s in rows if {"main", "F"} <= set(rows[s]))
for preset in ("hard", "default"):
    mine = [s for s in sets if s.startswith(preset)]
    if not mine:
        continue
    for var in ("main", "F"):
        vis = sum(rows[s][var]["visible"] for s in mine)
        acc = sum(rows[s][var]["accepted"] for s in mine)
        print(f"{preset} {var}: total {sum(rows[s][var]['score'] for s in mine)}, accepted {100 * acc / vis:.2f} %, "
              f"over 3 px {sum(rows[s][var]['over'] for s in mine)} ({len(mine)} sets)")
    print("  per set F - main:", ", ".join(f"{s} {rows[s]['F']['score'] - rows[s]['main']['score']:+d}" for s in mine))
