"""Per marker: the frames it is visible in both views (truth) but not accepted, and each view's status there
(0 tracked, 3 lost). usage: lost.py SET VARIANT (recs in /work/b43/rec)"""
import sys, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, accepted_sightings
from lipgen.recon.pipeline import Reconstruction
name, var = sys.argv[1], sys.argv[2]
t = load_truth(Dataset(f"/work/sets/{name}")); rec = Reconstruction.load(f"/work/b43/rec/{name}.{var}.npz")
acc = accepted_sightings(rec); vis = np.moveaxis(t["visible"], 1, 0).astype(bool)
names = rec.info["marker_names"]
both = vis.all(axis=0)
for k in range(len(names)):
    lostf = np.flatnonzero(both[:, k] & ~acc[:, k])
    if len(lostf):
        st = [rec.status[v][lostf, k] for v in range(2)]
        print(f"{names[k]:18s} lost {len(lostf):2d}/{int(both[:, k].sum())} frames {lostf.min()}-{lostf.max()} status v0 {np.bincount(st[0], minlength=5)} v1 {np.bincount(st[1], minlength=5)}")
print({k: v for k, v in rec.info.items() if k in ("walk_on", "gap_fill")})
