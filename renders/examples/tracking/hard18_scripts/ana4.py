import json, sys
import numpy as np
# Lures vs markers, mirror view: how many true-marker sightings (visible, at their nearest peak) pass a threshold,
# and how many lure peaks pass it, for abs thresholds and rel thresholds.
for s in sys.argv[1:]:
    R = json.load(open(f"{s}.json")); L = json.load(open(f"{s}_lures.json"))
    for v in (0, 1):
        rows = [r for r in R if r["v"] == v and r["dpk0"] <= 1.5]
        ab = np.array([r["pk0_str"] for r in rows]); rl = np.array([r["rel"] for r in rows])
        la = np.concatenate([l["abs"] for l in L if l["v"] == v]); lr = np.concatenate([l["rel"] for l in L if l["v"] == v])
        out = []
        for q in (0.03, 0.05, 0.10, 0.2):
            ta = np.quantile(ab, q); tr = np.quantile(rl, q)
            out.append(f"keep {1-q:.2f} of marker peaks: abs>={ta:.3f} lures {int((la>=ta).sum())} | rel>={tr:.3f} lures {int((lr>=tr).sum())}")
        print(s, "mirror" if v == 0 else "direct", len(rows), "marker peaks;", "\n   ".join([""] + out))
