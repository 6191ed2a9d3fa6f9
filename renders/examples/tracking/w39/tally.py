"""tally.py FILE... : per set, each variant's score, share and over, against main (from any of the files)."""
import json, sys, collections
rows = collections.defaultdict(dict)
for p in sys.argv[1:]:
    for line in open(p):
        r = json.loads(line); rows[r["set"]][r["variant"]] = r
vars_ = sorted({v for s in rows.values() for v in s if v != "main"})
tot = collections.Counter()
print("set".ljust(12), "main".ljust(22), *[v.ljust(24) for v in vars_])
for s in sorted(rows):
    m = rows[s].get("main")
    if not m: continue
    line = [s.ljust(12), f"{m['score']} ({m['share']}%, {m['over']})".ljust(22)]
    for v in vars_:
        r = rows[s].get(v)
        if r:
            line.append(f"{r['score'] - m['score']:+d} ({r['share']}%, {r['over']})".ljust(24))
            tot[v] += r["score"] - m["score"]; tot[v + "_n"] += 1
        else:
            line.append("-".ljust(24))
    print(*line)
print({k: v for k, v in tot.items()})
