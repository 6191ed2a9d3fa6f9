"""Markers wrong from their first accepted frame (over 3 px in both views there): at that frame, the
detector's peak nearest the true dot and the peak the marker took, per view (truth read; spent sets)."""
import sys, os, numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from spent import spent
from lipgen.recon.dots import as_gray, dot_peaks
root, var = sys.argv[1], sys.argv[2]
for name in sys.argv[3:]:
    d = spent(root, name, var)
    if d is None:
        continue
    ds, rec, acc, tuv, err, st = (d[k] for k in ("ds", "rec", "acc", "tuv", "err", "dots"))
    names = rec.info["marker_names"]
    right = []
    views0 = ds.rig.split_views(np.asarray(ds[0].image))
    for v in range(2):
        uv, s0, r0 = dot_peaks(as_gray(views0[v]), st)
        for k in np.flatnonzero(acc[0, :-1] & (err[v, 0, :-1] < 1.5)):
            d = np.linalg.norm(uv - rec.uv[v, 0, k], axis=1); i = int(np.argmin(d))
            if d[i] < 1.5: right.append(s0[i])
    right = np.array(right)
    print(f"{name}: right frame-0 peaks n={len(right)} strength median {np.median(right):.2f} 90% {np.percentile(right, 90):.2f} max {right.max():.2f}")
    for k in range(len(names) - 1):
        fa = np.flatnonzero(acc[:, k])
        if not len(fa) or not (err[:, fa[0], k] > 3).all():
            continue
        f = fa[0]; nwrong = int(((err[:, fa, k] > 3).all(axis=0)).sum())
        views = ds.rig.split_views(np.asarray(ds[f].image)); out = []
        for v in range(2):
            uv, s, r = dot_peaks(as_gray(views[v]), st)
            dt = np.linalg.norm(uv - tuv[v, f, k], axis=1); da = np.linalg.norm(uv - rec.uv[v, f, k], axis=1)
            i, j = int(np.argmin(dt)), int(np.argmin(da))
            out.append(f"v{v}: true-peak {dt[i]:.1f}px r{r[i]:.2f} s{s[i]:.2f} | took r{r[j]:.2f} s{s[j]:.2f} off {err[v, f, k]:.1f}")
        print(f"{name} {names[k]:18s} f{f} wrong {nwrong}/{len(fa)} | " + " || ".join(out), flush=True)
