"""Truth visibility vs rendered dot pixels (labels) per sighting."""
import sys, json, numpy as np
from lipgen.dataset.layout import Dataset
ds = Dataset(sys.argv[1])
labels = {v: int(k) for k, v in ds.manifest["mask_labels"].items()}

rows = []
for f in range(len(ds)):
    t = ds.truth(f); M = ds.mask(f)
    uv = t["uv_raw"]; vis = t["visible"]; dvf = t["dot_visible_fraction"]
    k = uv.shape[1]
    H, W = M.shape
    yy, xx = np.mgrid[0:H, 0:W]
    for v in range(2):
        for p in range(k):
            x, y = uv[v, p]
            if not np.isfinite(x): continue
            x0, x1, y0, y1 = int(max(0, x-6)), int(min(W, x+7)), int(max(0, y-6)), int(min(H, y+7))
            sub = M[y0:y1, x0:x1]
            lab = DOT0 = None
            lab = 10 + p
            n = int((sub == lab).sum())
            rows.append((f, v, p, bool(vis[v, p]), float(dvf[v, p]), n))
np.save(sys.argv[2], np.array(rows, dtype=float))
