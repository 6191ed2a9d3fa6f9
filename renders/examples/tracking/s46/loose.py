"""Would the 3-D judge do better measuring each run's point against the prediction's own spread (a Mahalanobis
distance under the physics prior conditioned on the other markers) than in mm? For each dispute span both runs
have pairs in (spent sets, truth read), the verdict at the judge's ratio from either distance.
loose.py DUMP SET...  (DUMP: s45/dump.py's OUT)"""
import os, sys, collections, numpy as np
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "s45"))
from dumped import dumped, right_run, spans
from lipgen.recon.crosscheck import layout_residuals

RATIO = 0.6
tally = collections.Counter()

for name, cap, tuv in dumped(sys.argv[1], sys.argv[2:]):
    a, b, disputed, cams, rest, cov, verdict = cap
    P = disputed.shape[1]
    ea, eb = layout_residuals(a, b, disputed, cams, rest, cov)[:2]               # mm
    ma, mb = layout_residuals(a, b, disputed, cams, rest, cov, spread=True)[:2]  # against the spread
    for m in range(P):
        for s, e in spans(disputed, m):
            ok = np.isfinite(ea[s:e, m]) & np.isfinite(eb[s:e, m])
            if not ok.any():
                continue
            who = right_run(a, b, tuv, s, e, m)
            for kind, x, y in (("mm", ea, eb), ("spread", ma, mb)):
                u, w = x[s:e, m][ok].mean(), y[s:e, m][ok].mean()
                tally[(who, kind, 2 if w < RATIO * u else 1 if u < RATIO * w else 0)] += e - s
            print(f"{name} {m:2d} frames {s}-{e - 1} right {who:7s} mm {ea[s:e, m][ok].mean():5.2f} "
                  f"{eb[s:e, m][ok].mean():5.2f} spread {ma[s:e, m][ok].mean():6.2f} {mb[s:e, m][ok].mean():6.2f}")
print("(right run, distance, verdict): frames")
for k in sorted(tally):
    print(" ", k, tally[k])
