"""Truth read (diagnosis only): the layout prediction of marker i from the TRUE positions of the others with its close
neighbour j also left out (j lost, as the check faces it): |pred_i - X_i| (own) and |pred_i - X_j| (how near the
prediction of i lands to j's true place), corner-region pairs, every 4th frame of the 14 development sets."""
import sys
import numpy as np
sys.path.insert(0, "/work/corner19")
from offline import *  # noqa
from lipgen.recon.firstframe import predict_layout
from lipgen.recon.lostneighbour import close_neighbours
from lipgen.rig.pinhole import triangulate
mesh = model_mesh("lip_mesh(0)"); rest = np.vstack([mesh.vertices[mesh.markers], mesh.nose]); names = [*mesh.marker_names, "nose"]
cov = physics_layout_covariance(Physics(mesh)); near, judged, width = close_neighbours(rest)
pairs = [("lower_corner_left", "corner_left"), ("upper_corner_left", "corner_left"), ("lower_corner_right", "corner_right"),
         ("upper_corner_right", "corner_right"), ("corner_left", "lower_corner_left"), ("corner_right", "lower_corner_right")]
res = {p: [] for p in pairs}
for name in sys.argv[1:]:
    ds = Dataset(DATA / name); cal = calibration(name, ds); T = lab_frame(cal)
    lab = cal.in_frame(T[:3, :3].T, -T[:3, :3].T @ T[:3, 3]); tu = load_truth(ds)["uv"]
    for t in range(0, tu.shape[0], 4):
        Xt = triangulate(lab.views[1], tu[t, 1], lab.views[0], tu[t, 0])[0]
        for a, b in pairs:
            i, j = names.index(a), names.index(b)
            use = np.all(np.isfinite(Xt), axis=1) & judged; use[[i, j]] = False
            pred = predict_layout(rest, np.where(use[:, None], Xt, 0), use, width, cov)
            res[(a, b)].append((name, np.linalg.norm(pred[i] - Xt[i]), np.linalg.norm(pred[i] - Xt[j])))
print(f"spacing {width:.2f} mm; pair (i, lost j): median |pred_i - X_i| / |pred_i - X_j|; sets where pred_i is nearer X_j than X_i")
for (a, b), v in res.items():
    own = np.array([x[1] for x in v]); oth = np.array([x[2] for x in v])
    sets = sorted({x[0] for x in v if x[2] < x[1]})
    print(f"  {a:19s} ({b:18s} lost): {np.median(own):.2f} / {np.median(oth):.2f}  nearer j in {100*np.mean(oth<own):.0f} % of frames: {' '.join(s.replace('hard_s','') for s in sets)}")
