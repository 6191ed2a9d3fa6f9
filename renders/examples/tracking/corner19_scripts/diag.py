import sys, json
import numpy as np
sys.path.insert(0, "/work/corner19")
from offline import *  # noqa
from lipgen.recon.lostneighbour import close_neighbours, run_distances, runs
from lipgen.rig.pinhole import triangulate
name = sys.argv[1]
ds = Dataset(DATA / name); cal = calibration(name, ds); T = lab_frame(cal)
lab = cal.in_frame(T[:3, :3].T, -T[:3, :3].T @ T[:3, 3])
mesh = model_mesh("lip_mesh(0)"); rest = np.vstack([mesh.vertices[mesh.markers], mesh.nose]); names = [*mesh.marker_names, "nose"]
cov = physics_layout_covariance(Physics(mesh))
m = np.load(ROOT / "out" / "main" / f"{name}.npz"); uv = m["uv"]; st = m["status"]
truth = load_truth(ds)
err = np.linalg.norm(uv - np.moveaxis(truth["uv"], 1, 0), axis=-1)  # (2,F,P)
near, judged, width = close_neighbours(rest)
print("width", width)
both = (st[0] != LOST) & (st[1] != LOST)
X = np.full(uv.shape[1:3] + (3,), np.nan)
X[both] = triangulate(lab.views[1], uv[1][both], lab.views[0], uv[0][both])[0]
acc = m["accepted"]
for i in np.flatnonzero(judged):
    for a, b in runs(both[:, i]):
        d_own, d_nb = run_distances(rest, X, both, i, range(a, b), near[i], width, cov)
        e = np.nanmedian(err[:, a:b, i]); over = int(((err[:, a:b, i] > 3) & acc[a:b, i]).sum())
        nb = {names[j]: round(float(np.nanmedian(d_nb[:, j])), 1) for j in range(len(rest)) if np.isfinite(d_nb[:, j]).any()}
        if over or nb:
            print(f"{names[i]:20s} {a:2d}-{b:2d} err {e:5.1f} over {over:3d} own {np.nanmedian(d_own) if np.isfinite(d_own).any() else np.nan:5.1f} nb {nb}")
