"""One marker's status and error per frame (REC_DIR: the recs, default /work/b40/rec). usage: marker.py SET VARIANT MARKER"""
import os, sys, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, accepted_sightings
from lipgen.recon.pipeline import Reconstruction
from lipgen.recon.modelmesh import model_mesh
names = [*model_mesh("lip_mesh(0)").marker_names, "nose"]
name, var, mk = sys.argv[1], sys.argv[2], names.index(sys.argv[3])
t = load_truth(Dataset(f"/work/sets/{name}")); rec = Reconstruction.load(f"{os.environ.get('REC_DIR', '/work/b40/rec')}/{name}.{var}.npz")
acc = accepted_sightings(rec); tuv = np.moveaxis(t["uv"], 1, 0); vis = np.moveaxis(t["visible"], 1, 0)
err = np.linalg.norm(rec.uv - tuv, axis=-1)
print("f  acc  vis0 vis1  st0 st1  err0  err1  gap")
for f in range(acc.shape[0]):
    print(f, int(acc[f, mk]), int(vis[0, f, mk]), int(vis[1, f, mk]), rec.status[0][f, mk], rec.status[1][f, mk],
          f"{err[0, f, mk]:5.1f} {err[1, f, mk]:5.1f} {rec.ray_gap[f, mk]:.2f}")
