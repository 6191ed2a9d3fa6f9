"""Would the 3-D judge do better measuring each run's point against the prediction's own spread (a Mahalanobis
distance under the physics prior conditioned on the other markers) than in mm? For each dispute span both runs
have pairs in (spent sets, truth read), the verdict at the judge's ratio from either distance.
loose.py DUMP SET...  (DUMP: s45/dump.py's OUT)"""
import os, sys, collections, numpy as np
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "s45"))
from dumped import dumped, right_run, spans
from lipgen.recon.layoutprior import predict_layout_physics
from lipgen.rig.pinhole import triangulate

RATIO = 0.6
tally = collections.Counter()


def points(run, cams):
    both = np.isfinite(run[0].uv).all(-1) & np.isfinite(run[1].uv).all(-1)
    X = np.full(both.shape + (3,), np.nan)
    X[both] = triangulate(cams[1], run[1].uv[both], cams[0], run[0].uv[both])[0]
    return X, both


for name, cap, tuv in dumped(sys.argv[1], sys.argv[2:]):
    a, b, disputed, cams, rest, cov, verdict = cap
    (Xa, both_a), (Xb, both_b) = points(a, cams), points(b, cams)
    F, P = disputed.shape
    ea, eb, ma, mb = (np.full((F, P), np.nan) for _ in range(4))
    for f in np.flatnonzero(disputed.any(axis=1)):
        use = both_a[f] & ~disputed[f]
        if use.sum() < 6:
            continue
        pred, loose = predict_layout_physics(rest, Xa[f], use, cov, spread=True)
        for m in np.flatnonzero(disputed[f] & both_a[f] & both_b[f]):
            inv = np.linalg.inv(loose[m])
            for X, e, mm in ((Xa, ea, ma), (Xb, eb, mb)):
                d = X[f, m] - pred[m]
                e[f, m], mm[f, m] = np.linalg.norm(d), np.sqrt(d @ inv @ d)
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
