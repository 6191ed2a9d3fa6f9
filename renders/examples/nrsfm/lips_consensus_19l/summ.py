import json, sys, numpy as np
rows = [json.loads(l) for f in sys.argv[1:] for l in open(f) if l.strip()]
RS = ["Rinf", "R100", "R30", "R10", "R5", "R3"]
for R in RS:
    vals = [r.get(R, r["auto"]) for r in rows]
    worse = [r["name"] for r, v in zip(rows, vals) if v > r["flat"] * (1 + 1e-9)]
    print(R, "n", len(rows), "mean %.4f" % np.mean(vals), "worse", len(worse), worse[:6])
