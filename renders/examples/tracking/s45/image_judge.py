"""Would the judge do better in the image than in 3-D? For each dispute span both runs have pairs in (spent sets,
truth read): the 3-D verdict against one from the mean pixel distance of each run's sightings to the projected
prediction (both views), at the same ratio. image_judge.py DUMP SET..."""
import os, sys, collections, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from dumped import dumped, right_run, spans
from lipgen.recon.crosscheck import layout_residuals

RATIO = 0.6
tally = collections.Counter()
for name, cap, tuv in dumped(sys.argv[1], sys.argv[2:]):
    a, b, disputed, cams, rest, cov, verdict = cap
    ra, rb, predicted, both_a, both_b = layout_residuals(a, b, disputed, cams, rest, cov)
    pa = np.full((2,) + predicted.shape[:2] + (2,), np.nan)      # (2, F, P, 2) the prediction's projections
    has = np.all(np.isfinite(predicted), axis=-1)
    for v, c in enumerate(cams):
        pa[v][has] = c.project(predicted[has])
    da = np.mean([np.linalg.norm(a[v].uv - pa[v], axis=-1) for v in range(2)], axis=0)
    db = np.mean([np.linalg.norm(b[v].uv - pa[v], axis=-1) for v in range(2)], axis=0)
    for m in range(disputed.shape[1]):
        for s, e in spans(disputed, m):
            ok = np.isfinite(ra[s:e, m]) & np.isfinite(rb[s:e, m])
            if not ok.any():
                continue
            who = right_run(a, b, tuv, s, e, m)
            x, y = ra[s:e, m][ok].mean(), rb[s:e, m][ok].mean()
            v3 = 2 if y < RATIO * x else 1 if x < RATIO * y else 0
            x, y = da[s:e, m][ok].mean(), db[s:e, m][ok].mean()
            v2 = 2 if y < RATIO * x else 1 if x < RATIO * y else 0
            tally[(who, "3-D", v3)] += e - s
            tally[(who, "image", v2)] += e - s
print("(right run, judge, verdict): frames; with keep_undecided 0 counts as 1")
for k in sorted(tally):
    print(" ", k, tally[k])
