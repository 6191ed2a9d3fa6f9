import json, sys
import numpy as np
for s in sys.argv[1:]:
    R = json.load(open(f"{s}.json"))
    for v in (0, 1):
        for nm, sel in (("acc", [r for r in R if r["v"] == v and r["acc"]]), ("lost", [r for r in R if r["v"] == v and not r["acc"] and r["status"] == 3])):
            n = len(sel)
            if not n: continue
            A = lambda k: np.array([r[k] for r in sel])
            det = (A("dpk") <= 1.5)
            round_det = det & (A("pk_rnd") >= 0.3)
            elong = det & ~round_det
            anypk = A("dpk0") <= 1.5
            faint = ~det & anypk & (A("pk0_str") < A("floor"))
            faint_rnd = faint & (A("pk0_rnd") >= 0.3)
            merged = ~anypk
            print(f"{s} {'mirror' if v==0 else 'direct'} {nm:4s} n={n:4d}: round dot within 1.5px {round_det.sum():4d} | elongated {elong.sum():3d} | peak under floor {faint.sum():3d} (round {faint_rnd.sum()}) | other peak-only {(~det & anypk & ~faint).sum():3d} | no peak within 1.5 px (merged/none) {merged.sum():3d}; nn dist med {np.median(A('nn')):.1f}px; floor med {np.median(A('floor')):.3f}")
