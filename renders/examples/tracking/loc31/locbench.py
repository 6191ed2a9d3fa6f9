"""Localization only: refine_centroids started near the true projection of every visible mark.
python locbench.py VARIANT DATASET... (every 3rd frame; start offset uniform in a 0.7 px disc, seeded)"""
import sys, json, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.recon.dots import ink_gray, refine_centroids
import variants
var = sys.argv[1]
rows = {}
for path in sys.argv[2:]:
    ds = Dataset(path); rig = ds.rig
    marks0 = np.asarray(ds.truth(0)["marks_world"]).mean(0)
    ppm = min(c.K[0, 0] / (c.R @ marks0 + c.t)[2] for c in rig.views)
    sigma = float(np.clip(0.85 * float(ds.settings.dot_diameter) / 2 * ppm, 1.2, 6.0))
    rng = np.random.default_rng(0)
    errs = {0: [], 1: []}; names = list(ds.manifest["marks"])
    per = {}
    for i in range(0, len(ds), 3):
        t = ds.truth(i); views = rig.split_views(ds[i].image)
        for v in (0, 1):
            vis = np.asarray(t["visible"][v], bool); uv = np.asarray(t["uv"][v])[vis]
            a = rng.uniform(0, 2 * np.pi, len(uv)); r = 0.7 * np.sqrt(rng.uniform(0, 1, len(uv)))
            start = uv + np.stack([r * np.cos(a), r * np.sin(a)], 1)
            variants.SIDE[0] = "vr"[v]; got = variants.locate(var, views[v], start, sigma)
            e = np.linalg.norm(got - uv, axis=1)
            errs[v] += e.tolist()
            for p, ee in zip(np.flatnonzero(vis), e):
                per.setdefault(names[p], []).append(ee)
    out = {"set": path.rstrip("/").split("/")[-1], "var": var, "sigma": round(sigma, 2)}
    for v in (0, 1):
        e = np.array(errs[v]); out["VR"[v]] = round(float(np.sqrt(np.mean(np.minimum(e, 3) ** 2))), 3)
        out["VR"[v] + "_over1.5"] = int((e > 1.5).sum())
    out["nose"] = round(float(np.sqrt(np.mean(np.minimum(per["nose"], 3) ** 2))), 3)
    print(json.dumps(out), flush=True)
