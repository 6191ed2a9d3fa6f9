"""The frames cross_check_pairs judges on spent sets (truth read): the 2-D distances to the projected prediction
of the one-view sighting and of the other run's pair, the verdict, and which was right.
pairs.py DUMP SET...  (DUMP: dump.py's OUT)"""
import os, sys, collections, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from dumped import dumped
from lipgen.recon.crosscheck import arbitrate, layout_residuals, view_distances

tally = collections.Counter()
for name, cap, tuv in dumped(sys.argv[1], sys.argv[2:]):
    a, b, disputed, cams, rest, cov, _ = cap
    plain = arbitrate(a, b, disputed, cams, rest, cov)
    paired = arbitrate(a, b, disputed, cams, rest, cov, pairs=True)
    ra, rb, predicted, both_a, both_b = layout_residuals(a, b, disputed, cams, rest, cov)
    judged = disputed & ~(np.isfinite(ra) & np.isfinite(rb)) & (plain == 0) & (both_a != both_b)
    judged &= np.all(np.isfinite(predicted), axis=-1)
    for f, m in np.argwhere(judged):
        pair, single = (a, b) if both_a[f, m] else (b, a)
        d_single, d_pair = view_distances(pair, single, f, m, predicted[f, m], cams)
        e_pair = max(np.linalg.norm(pair[v].uv[f, m] - tuv[v, f, m]) for v in range(2))
        e_single = np.nanmin([np.linalg.norm(single[v].uv[f, m] - tuv[v, f, m]) for v in range(2)])
        right = "pair" if e_pair <= 3 < e_single else "single" if e_single <= 3 < e_pair else \
            "both" if e_pair <= 3 else "neither"
        tally[("pair is " + ("A" if both_a[f, m] else "B"), "right: " + right, int(paired[f, m]))] += 1
        print(f"{name} frame {f:2d} marker {m:2d} pair {'A' if both_a[f, m] else 'B'} d_single {d_single:5.1f} "
              f"d_pair {d_pair:5.1f} px verdict {paired[f, m]} truth: pair {e_pair:5.1f} single {e_single:5.1f} px")
print("\n(pair run, which was right, verdict with pairs): frames")
for k in sorted(tally):
    print(" ", k, tally[k])
