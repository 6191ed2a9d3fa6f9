import sys, os, numpy as np
sys.path.insert(0, "/work/b35")
os.environ.setdefault("X", "1")
from ffh import setup
from emlabel import Layout, fit, labels
from lipgen.recon.firstframe import first_frame_dots
from lipgen.rig.pinhole import triangulate
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from scipy.spatial.transform import Rotation
from lipgen.recon.stereo_init import _similarity_3d
path = sys.argv[1]; scale = float(sys.argv[2]); k = int(sys.argv[3]); sig0 = float(sys.argv[4])
g = setup(path); ds = Dataset(path); t = load_truth(ds); S = g["settings"]; cams = g["cameras"]; names = g["names"]
lay = Layout(g["rest_points"], g["layout_covariance"], scale)
uv = t["uv"][k]
Xt = triangulate(cams[1], uv[1], cams[0], uv[0])[0]
T = _similarity_3d(lay.m, Xt); R = T[:3, :3]; s = np.cbrt(np.linalg.det(R))
th0 = np.zeros(7 + lay.k); th0[:3] = Rotation.from_matrix(R / s).as_rotvec(); th0[6] = np.log(s); th0[3:6] = T[:3, 3] + R @ lay.c - lay.c
views = g["rig"].split_views(np.asarray(ds[k].image))
det = first_frame_dots(views, S.tracker.dots, g["expected"], S.init_gate, S.robust_first_frame, S.first_frame_dark, S.first_frame_floor, S.tracker.floor_min)
dots = [d[0] for d in det]
print("dots per view", [len(d) for d in dots])
X0 = lay.points(th0)
th = fit(dots, cams, lay, th0=th0, sigmas=np.geomspace(sig0, 1.5, 10))
X = lay.points(th)
lab = labels(dots, cams, lay, th)
print("3D err RMS init %.2f fitted %.2f mm; |a| %.1f" % (np.sqrt(((X0 - Xt)**2).sum(1).mean()), np.sqrt(((X - Xt)**2).sum(1).mean()), np.linalg.norm(th[7:])))
for v in range(2):
    u = cams[v].project(X); u0 = cams[v].project(X0)
    dn = np.linalg.norm(dots[v][:, None] - uv[v][None], axis=2)
    for i, nm in enumerate(names):
        j = lab[v][i]
        e = np.linalg.norm(dots[v][j] - uv[v][i]) if j >= 0 else np.nan
        print(f"v{v} {nm:20s} init {np.linalg.norm(u0[i]-uv[v][i]):5.1f} fit {np.linalg.norm(u[i]-uv[v][i]):5.1f}px  truth-dot {dn[:, i].min():5.1f}  label err {e:5.1f}")
