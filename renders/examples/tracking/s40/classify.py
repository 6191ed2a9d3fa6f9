"""Classify accepted sightings over 3 px: set, marker, view, frames, error, whose true dot it sits on, and
whether the marker was wrong from its first accepted frame. REC_DIR: the recs (default /work/b40/rec)."""
import os, sys, numpy as np, collections
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, accepted_sightings
from lipgen.recon.pipeline import Reconstruction
from lipgen.recon.modelmesh import model_mesh
names = [*model_mesh("lip_mesh(0)").marker_names, "nose"]
var = sys.argv[1]
for name in sys.argv[2:]:
    t = load_truth(Dataset(f"/work/sets/{name}"))
    rec = Reconstruction.load(f"{os.environ.get('REC_DIR', '/work/b40/rec')}/{name}.{var}.npz")
    acc = accepted_sightings(rec)
    tuv = np.moveaxis(t["uv"], 1, 0); vis = np.moveaxis(t["visible"], 1, 0).astype(bool)
    P = rec.visible.shape[1]
    err = np.linalg.norm(rec.uv - tuv, axis=-1)
    over = acc[None] & vis & (err > 3)
    print(f"== {name}: over {int(over.sum())}")
    for k in range(P + 1):
        for v in range(2):
            fr = np.flatnonzero(over[v, :, k])
            if not len(fr):
                continue
            on = collections.Counter()
            for f in fr:
                d = np.linalg.norm(tuv[v, f] - rec.uv[v, f, k], axis=-1); d[k] = np.inf
                j = int(np.argmin(d)); on[names[j] if d[j] < 2 else "none"] += 1
            first = np.flatnonzero(acc[:, k])[0]
            print(f"  {names[k]:20s} v{v} n={len(fr):3d} frames {fr[0]}-{fr[-1]} first_acc {first} "
                  f"err med {np.median(err[v, fr, k]):.1f} on {dict(on)}")
