"""Development totals: main, BHC, BHC2 over the 21 sets (dev.jsonl, probe128.jsonl, dev2.jsonl, probe2.jsonl)."""
import json
rows = []
for f in ("dev.jsonl", "probe128.jsonl", "dev2.jsonl", "probe2.jsonl"):
    rows += [json.loads(l) for l in open(f)]
d = {(r["set"], r["variant"]): r for r in rows}
sets = sorted({s for s, _ in d}, key=lambda s: (s.split("_")[0], int(s.split("_")[1])))
tot = {}
for s in sets:
    line = [s]
    for v in ("main", "BH", "BHC", "BHC2"):
        r = d.get((s, v))
        if r:
            tot[v] = tot.get(v, 0) + r["score"]
            line.append(f"{v} {r['score']} ({r['share']}/{r['over']})")
    print("  ".join(line))
print(tot)
