"""Score the EM labeller on frames (as ffh.py), same dots as main's first frame.
usage: ffem.py OUT.jsonl STEP SCALE SET..."""
import sys, os, json, numpy as np
sys.path.insert(0, "/work/b35")
from ffh import setup
from emlabel import Layout, fit, labels
from lipgen.recon.firstframe import first_frame_dots
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen._threads import blas_threads

ORACLE = os.environ.get("ORACLE") == "1"
SIGMAS = np.geomspace(float(os.environ.get("SIG0", 25)), 1.5, 10)
from scipy.spatial.transform import Rotation
def oracle_theta(lay, Xt):
    from lipgen.recon.stereo_init import _similarity_3d
    T = _similarity_3d(lay.m, Xt); R = T[:3, :3]; s = np.cbrt(np.linalg.det(R)); Rn = R / s
    th = np.zeros(7 + lay.k); th[:3] = Rotation.from_matrix(Rn).as_rotvec(); th[6] = np.log(s)
    # X = s Rn (m - c) + c + t  ==  s Rn m + T3  ->  t = T3 + s Rn c - c
    th[3:6] = T[:3, 3] + R @ lay.c - lay.c
    return th
out = open(sys.argv[1], "a"); step = int(sys.argv[2]); scale = float(sys.argv[3])
for path in sys.argv[4:]:
    g = setup(path); ds = Dataset(path); names = g["names"]; t = load_truth(ds); S = g["settings"]
    lay = Layout(g["rest_points"], g["layout_covariance"], scale)
    for k in range(0, len(ds), step):
        views = g["rig"].split_views(np.asarray(ds[k].image))
        with blas_threads(1):
            det = first_frame_dots(views, S.tracker.dots, g["expected"], S.init_gate, S.robust_first_frame,
                                   S.first_frame_dark, S.first_frame_floor, S.tracker.floor_min)
            dots = [d[0] for d in det]
            th0 = None
            if ORACLE:
                from lipgen.rig.pinhole import triangulate
                Xt = triangulate(g["cameras"][1], t["uv"][k][1], g["cameras"][0], t["uv"][k][0])[0]
                th0 = oracle_theta(lay, Xt)
            th = fit(dots, g["cameras"], lay, th0=th0, sigmas=SIGMAS)
            lab = labels(dots, g["cameras"], lay, th)
        uv = t["uv"][k]
        inits = np.stack([np.where((lab[v] >= 0)[:, None], dots[v][np.maximum(lab[v], 0)], np.nan) if len(dots[v])
                          else np.full((len(names), 2), np.nan) for v in range(2)])
        err = np.linalg.norm(inits - uv, axis=2); seen = np.isfinite(err)
        right = (seen & (err <= 3)).all(0); wrong = (seen & (err > 3)).any(0)
        wv = (seen & (err > 3)).sum(1)
        row = dict(set=os.path.basename(path.rstrip('/')), frame=k, right=int(right.sum()), wrong=int(wrong.sum()),
                   wrong_v=int(wv[0]), wrong_r=int(wv[1]), one_view_right=int(((seen & (err <= 3)).any(0)).sum()),
                   wrong_names=[names[i] for i in np.flatnonzero(wrong)],
                   rot_deg=float(np.degrees(np.linalg.norm(th[:3]))), t=th[3:6].round(2).tolist(), s=float(np.exp(th[6])))
        print(json.dumps(row), file=out, flush=True)
