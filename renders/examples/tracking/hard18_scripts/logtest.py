"""Would a Laplacian-of-Gaussian blob response have a peak at the mirror's unresolved ('nopeak') dots?"""
import json, sys
import numpy as np
from scipy import ndimage
from lipgen.dataset.layout import Dataset
from lipgen.recon.dots import ink_gray
s = sys.argv[1]; sigma = 1.28
ds = Dataset(f"/work/data/{s}"); R = json.load(open(f"{s}.json"))
res = {}
for scale in (1.0, 1.5, 2.0):
    res[scale] = dict(nopeak_hit=0, nopeak=0, acc_hit=0, acc=0, lures=0, frames=0)
byf = {}
for r in R:
    if r["v"] == 0:
        byf.setdefault(r["f"], []).append(r)
for f, rows in byf.items():
    g = ink_gray(ds.rig.split_views(ds[f].image)[0])
    t = ds.truth(f)["uv"][0]
    tt = t[np.isfinite(t).all(1)]
    lo = np.maximum(np.floor(tt.min(0) - 60).astype(int), 0); hi = np.minimum(np.ceil(tt.max(0) + 60).astype(int), g.shape[::-1])
    for scale in res:
        L = scale ** 2 * sigma ** 2 * ndimage.gaussian_laplace(g, scale * sigma)   # dark blob -> positive
        sub = L[lo[1]:hi[1], lo[0]:hi[0]]
        med = np.median(sub); mad = 1.4826 * np.median(np.abs(sub - med))
        pk = (sub == ndimage.maximum_filter(sub, 3)) & (sub > med + 4.5 * mad)
        ys, xs = np.nonzero(pk); P = np.column_stack([xs + lo[0], ys + lo[1]]).astype(float)
        d = np.linalg.norm(P[:, None] - tt[None], axis=2).min(1) if len(P) else np.zeros(0)
        res[scale]["lures"] += int((d > 3).sum()); res[scale]["frames"] += 1
        val = sub[ys, xs]
        res[scale].setdefault("lure_vals", []).extend(val[d > 3].tolist())
        for r in rows:
            dd = np.linalg.norm(P - t[r["p"]], axis=1) if len(P) else np.array([np.inf])
            hit = dd.min() <= 1.5
            if hit:
                res[scale].setdefault("mark_vals", []).append(float(val[dd.argmin()]))
            k = "nopeak" if (not r["acc"] and r["status"] == 3 and r["dpk0"] > 1.5) else ("acc" if r["acc"] else None)
            if k:
                res[scale][k] += 1; res[scale][k + "_hit"] += int(bool(hit))
for sc, v in res.items():
    mv, lv = np.array(v.pop("mark_vals")), np.array(v.pop("lure_vals"))
    qs = " | ".join(f"keep {1-q:.2f} of marker peaks: lures {int((lv >= np.quantile(mv, q)).sum())}" for q in (0.03, 0.05, 0.1, 0.2))
    print(s, sc, json.dumps(v), "\n    ", qs)
