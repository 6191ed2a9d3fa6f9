import sys
import numpy as np
sys.path.insert(0, "/work/corner19")
from offline import *  # noqa
from lipgen.recon.firstframe import predict_layout
from lipgen.recon.lostneighbour import close_neighbours
from lipgen.rig.pinhole import triangulate
name = sys.argv[1]; a, b = sys.argv[2], sys.argv[3]
ds = Dataset(DATA / name); cal = calibration(name, ds); T = lab_frame(cal)
lab = cal.in_frame(T[:3, :3].T, -T[:3, :3].T @ T[:3, 3])
mesh = model_mesh("lip_mesh(0)"); rest = np.vstack([mesh.vertices[mesh.markers], mesh.nose]); names = [*mesh.marker_names, "nose"]
cov = physics_layout_covariance(Physics(mesh))
truth = load_truth(ds); tu = truth["uv"]  # (F,2,P,2)
F = tu.shape[0]
i, j = names.index(a), names.index(b)
_, _, width = close_neighbours(rest)
print("rest dist", np.linalg.norm(rest[i] - rest[j]).round(2), "width", round(width, 2))
for t in range(0, F, 5):
    X = triangulate(lab.views[1], tu[t, 1], lab.views[0], tu[t, 0])[0]
    use = np.all(np.isfinite(X), axis=1); use[[i, j]] = False
    pred = predict_layout(rest, np.where(use[:, None], X, 0), use, width, cov)
    print(t, "true dist", np.linalg.norm(X[i] - X[j]).round(2), "pred err own", np.linalg.norm(pred[i] - X[i]).round(2),
          "nb", np.linalg.norm(pred[j] - X[j]).round(2), "pred i-j", np.linalg.norm(pred[i] - pred[j]).round(2), "pred_i to X_j", np.linalg.norm(pred[i] - X[j]).round(2), "pred_j to X_i", np.linalg.norm(pred[j] - X[i]).round(2))
