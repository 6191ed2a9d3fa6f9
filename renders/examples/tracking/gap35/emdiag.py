import sys, numpy as np
sys.path.insert(0, "/work/b35")
from ffh import setup
from emlabel import Layout, fit, labels, _rot
from lipgen.recon.firstframe import first_frame_dots
from lipgen.recon.stereo_init import _similarity_3d
from lipgen.rig.pinhole import triangulate
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
path = sys.argv[1]; scale = float(sys.argv[2])
g = setup(path); ds = Dataset(path); t = load_truth(ds); S = g["settings"]; cams = g["cameras"]
lay = Layout(g["rest_points"], g["layout_covariance"], scale)
print("modes", lay.k, "P", lay.P)
for k in map(int, sys.argv[3:]):
    uv = t["uv"][k]
    X = triangulate(cams[1], uv[1], cams[0], uv[0])[0]
    M = g["rest_points"]
    T = _similarity_3d(M, X)
    R = T[:3, :3]; s = np.cbrt(np.linalg.det(R)); Rn = R / s
    ang = np.degrees(np.arccos(np.clip((np.trace(Rn) - 1) / 2, -1, 1)))
    res = X - (M @ R.T + T[:3, 3])
    print(f"frame {k}: similarity turn {ang:.1f} deg scale {s:.3f} shift {np.linalg.norm(T[:3,3] + (R - np.eye(3)) @ lay.c):.2f} mm; residual RMS {np.sqrt((res**2).sum(1).mean()):.2f} mm max {np.linalg.norm(res,axis=1).max():.2f}")
    exp = np.stack([c.project(M) for c in cams])
    print("   expected vs truth px: median", np.median(np.linalg.norm(exp - uv, axis=2), axis=1).round(1))
    # ideal theta: fit EM to the truth uv as 'dots' (small sigma)
    th = fit([uv[0], uv[1]], cams, lay, sigmas=np.geomspace(25, 1.0, 10))
    Xf = lay.points(th)
    print(f"   EM on truth dots: turn {np.degrees(np.linalg.norm(th[:3])):.1f} t {th[3:6].round(2)} s {np.exp(th[6]):.3f} |a| {np.linalg.norm(th[7:]):.1f}; 3D err RMS {np.sqrt(((Xf-X)**2).sum(1).mean()):.2f} mm")
