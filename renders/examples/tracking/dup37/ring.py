"""Ring test diagnostic: around each accepted sighting, the darkest ring sector's contrast relative to the median ring."""
import sys, json, numpy as np
from scipy.ndimage import map_coordinates
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.dataset.layout import Dataset
from lipgen.recon.pipeline import Reconstruction
out = open(sys.argv[1], "w"); R = float(sys.argv[2])
for arg in sys.argv[3:]:
    s, path = arg.split("=")
    ds = Dataset(f"/work/sets/{s}"); tr = load_truth(ds); rec = Reconstruction.load(path)
    sig = rec.info["settings"]["tracker"]["dots"]["sigma"]
    e = sighting_errors(tr, rec)
    ang = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    for f in range(len(ds)):
        views = ds.rig.split_views(np.asarray(ds[f].image))
        for v, view in enumerate(e):
            img = np.asarray(views[v], float); g = img.mean(-1) if img.ndim == 3 else img
            for p in np.flatnonzero(e[view]["ok"][f]):
                u, w = rec.uv[v, f, p]
                cen = map_coordinates(g, [[w], [u]], order=1)[0]
                rad = R * sig
                ring = map_coordinates(g, [w + rad * np.sin(ang), u + rad * np.cos(ang)], order=1)
                sect = np.convolve(np.r_[ring, ring[:3]], np.ones(4) / 4, "valid")[:24]   # 4-sample sectors
                med = np.median(ring)
                d = np.linalg.norm(tr["uv"][f, v] - rec.uv[v, f, p], axis=-1); d[p] = np.inf
                kind = "right" if e[view]["err"][f, p] <= 3 else ("neigh" if np.nanmin(d) < 1.5 else "lure")
                print(json.dumps({"set": s, "f": f, "v": v, "p": int(p), "kind": kind,
                                  "q": float((sect.min() - cen) / max(med - cen, 1e-6)), "c": float(med - cen)}), file=out)
