"""Truth read to judge the premise (diagnosis only): per marker run with a close neighbour lost, the run's medians
d_own, d_nb (as the check computes them on main's tracks) for runs wrong (median error > 3 px) vs right; and the layout
prediction's own error from the TRUE positions of all other markers, per corner marker."""
import sys
import numpy as np
sys.path.insert(0, "/work/corner19")
from offline import *  # noqa
from lipgen.recon.firstframe import predict_layout
from lipgen.recon.lostneighbour import close_neighbours, run_distances, runs
from lipgen.rig.pinhole import triangulate
mesh = model_mesh("lip_mesh(0)"); rest = np.vstack([mesh.vertices[mesh.markers], mesh.nose]); names = [*mesh.marker_names, "nose"]
cov = physics_layout_covariance(Physics(mesh))
near, judged, width = close_neighbours(rest)
rows, perr = [], {}
for name in sys.argv[1:]:
    ds = Dataset(DATA / name); cal = calibration(name, ds); T = lab_frame(cal)
    lab = cal.in_frame(T[:3, :3].T, -T[:3, :3].T @ T[:3, 3])
    m = np.load(ROOT / "out" / "main" / f"{name}.npz"); uv = m["uv"]; st = m["status"]; acc = m["accepted"]
    truth = load_truth(ds); tu = truth["uv"]
    err = np.linalg.norm(uv - np.moveaxis(tu, 1, 0), axis=-1)
    both = (st[0] != LOST) & (st[1] != LOST)
    X = np.full(uv.shape[1:3] + (3,), np.nan)
    X[both] = triangulate(lab.views[1], uv[1][both], lab.views[0], uv[0][both])[0]
    for i in np.flatnonzero(judged):
        for a, b in runs(both[:, i]):
            d_own, d_nb = run_distances(rest, X, both, i, range(a, b), near[i], width, cov)
            ok = np.isfinite(d_own)
            if not ok.any():
                continue
            nbm = [np.median(d_nb[ok & np.isfinite(d_nb[:, j]), j]) for j in range(len(rest)) if (ok & np.isfinite(d_nb[:, j])).any()]
            e = np.nanmedian(err[:, a:b, i])
            rows.append((name, names[i], b - a, e > 3, float(np.median(d_own[ok])), min(nbm), int((acc[a:b, i] & (err[:, a:b, i] > 3)).sum())))
    for t in range(0, uv.shape[1], 4):
        Xt = triangulate(lab.views[1], tu[t, 1], lab.views[0], tu[t, 0])[0]
        for i in np.flatnonzero(judged):
            use = np.all(np.isfinite(Xt), axis=1) & judged; use[i] = False
            if np.isfinite(Xt[i]).all():
                pred = predict_layout(rest, np.where(use[:, None], Xt, 0), use, width, cov)
                perr.setdefault(names[i], []).append(np.linalg.norm(pred[i] - Xt[i]))
r = rows
wrong = [x for x in r if x[3]]; right = [x for x in r if not x[3]]
f = lambda xs, k: np.percentile([x[k] for x in xs], [10, 50, 90]).round(2) if xs else None
print(f"layout spacing {width:.2f} mm; runs with a lost close neighbour: wrong {len(wrong)} (over-3-px accepted {sum(x[6] for x in wrong)}), right {len(right)}")
print("d_own p10/50/90  wrong", f(wrong, 4), " right", f(right, 4))
print("d_nb  p10/50/90  wrong", f(wrong, 5), " right", f(right, 5))
rw = [x[5] / x[4] for x in wrong]; rr = [x[5] / x[4] for x in right]
print("d_nb/d_own p10/50/90 wrong", np.percentile(rw, [10, 50, 90]).round(2), " right", np.percentile(rr, [10, 50, 90]).round(2))
print("wrong runs with d_nb < d_own:", sum(x < 1 for x in rw), "of", len(rw), "; right runs:", sum(x < 1 for x in rr), "of", len(rr))
for x in sorted(wrong, key=lambda x: -x[6]):
    print(f"  wrong {x[0]:10s} {x[1]:20s} {x[2]:3d} frames  d_own {x[4]:.1f}  d_nb {x[5]:.1f}  over3 {x[6]}")
print("layout prediction error from the true positions of the others (mm, median / p90 over sets x frames):")
for k, v in perr.items():
    print(f"  {k:20s} {np.median(v):.2f} / {np.percentile(v, 90):.2f}")
