"""hard (main): the angle between each dot's normal and its ray in each view, for accepted and lost sightings."""
import sys, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import Reconstruction
VIEWS = ("virtual", "real")
acc = {v: [] for v in VIEWS}; lost = {v: [] for v in VIEWS}
for arg in sys.argv[1:]:
    setdir, rec = arg.split(":")
    ds = Dataset(setdir); tr = load_truth(ds); r = Reconstruction.load(rec); e = sighting_errors(tr, r)
    views = ds.rig.views
    F = r.status.shape[1]
    for f in range(F):
        t = ds.truth(f)
        X, N = t["marks_world"], t["normals_world"]
        for vi, v in enumerate(VIEWS):
            cam = views[vi]
            C = np.asarray(cam.center, dtype=float)
            ray = C[None] - X
            ray /= np.linalg.norm(ray, axis=1, keepdims=True)
            cosang = np.einsum("ij,ij->i", ray, N / np.linalg.norm(N, axis=1, keepdims=True))
            ang = np.degrees(np.arccos(np.clip(np.abs(cosang), 0, 1)))
            ok = e[v]["ok"][f]; lo = e[v]["truly"][f] & ~e[v]["got"][f]
            acc[v].append(ang[ok]); lost[v].append(ang[lo])
for v in VIEWS:
    a, l = np.concatenate(acc[v]), np.concatenate(lost[v])
    print(f"{v}: accepted {len(a)} angle p10/50/90 {np.round(np.percentile(a, [10, 50, 90]), 1)}; "
          f"lost {len(l)} {np.round(np.percentile(l, [10, 50, 90]), 1)}; "
          f"share over 60 deg: accepted {np.mean(a > 60):.3f}, lost {np.mean(l > 60):.3f}")
