"""For every accepted sighting: the distance (direct view) to the nearest detector peak that no accepted marker
holds, split by right (< 1.5 px in both views) and wrong (> 3 px in both) -- truth read; spent sets."""
import sys, os, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from spent import spent
from lipgen.recon.dots import as_gray, dot_peaks
root, var, view = sys.argv[1], sys.argv[2], int(sys.argv[3])
for name in sys.argv[4:]:
    d = spent(root, name, var)
    if d is None:
        continue
    ds, rec, acc, err, st = d["ds"], d["rec"], d["acc"], d["err"], d["dots"]
    right, wrong = [], []
    for f in range(acc.shape[0]):
        uv, s, r = dot_peaks(as_gray(ds.rig.split_views(np.asarray(ds[f].image))[view]), st)
        held = rec.uv[view, f][acc[f]]
        free = uv[np.linalg.norm(uv[:, None] - held[None], axis=-1).min(axis=1) > 2.0]
        for k in np.flatnonzero(acc[f, :-1]):
            d = np.linalg.norm(free - rec.uv[view, f, k], axis=1).min() if len(free) else np.inf
            if (err[:, f, k] < 1.5).all(): right.append(d)
            elif (err[:, f, k] > 3).all(): wrong.append(d)
    right, wrong = np.array(right), np.array(wrong)
    row = [f"{name} view{view} right {len(right)} wrong {len(wrong)}"]
    for lim in (4, 6, 8, 10, 12):
        row.append(f"<={lim}px: right {np.mean(right <= lim)*100:.1f}% wrong {np.mean(wrong <= lim)*100 if len(wrong) else float('nan'):.0f}%")
    print(" | ".join(row), flush=True)
