"""For a marker seen in one view only, the other view's candidates on its epipolar band."""
import sys, numpy as np
sys.path.insert(0, "/work/b35")
from ffh import setup
from dataclasses import replace
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen.recon.pipeline import Reconstruction
from lipgen.recon.dots import detect_dots, ink_gray, refine_centroids
from lipgen.recon.blobs import _pit_peaks
from lipgen.recon.firstframe import predict_layout
from lipgen.recon.pointreg import layout_spacing
from lipgen.rig.pinhole import triangulate
path, mark = sys.argv[1], sys.argv[2]; frames = list(map(int, sys.argv[3:]))
name = path.rstrip("/").split("/")[-1]
g = setup(path); ds = Dataset(path); t = load_truth(ds); rec = Reconstruction.load(f"/work/b35/rec/{name}.main.npz")
cams = g["cameras"]; rest = g["rest_points"]; cov = g["layout_covariance"]; names = g["names"]; i = names.index(mark)
S = g["settings"].tracker.dots; width = layout_spacing(rest)
gapmax = rec.info["ray_gap_limit_mm"]
print("ray gap limit", gapmax, "spacing", width)
for f in frames:
    seen = np.stack([rec.status[v][f] != 3 for v in range(2)])
    A = 1 if seen[1, i] and not seen[0, i] else 0
    B = 1 - A
    both = seen.all(0) & (rec.ray_gap[f] <= gapmax)
    X = np.full((len(names), 3), np.nan)
    X[both] = triangulate(cams[1], rec.uv[1][f][both], cams[0], rec.uv[0][f][both])[0]
    pred = predict_layout(rest, X, both, width, cov)
    img = g["rig"].split_views(np.asarray(ds[f].image))[B]
    uv1, st = detect_dots(img, replace(S, min_contrast=0.05))
    r, c = _pit_peaks(ink_gray(img), S)
    pk = np.vstack([uv1, np.column_stack([c, r]).astype(float)])
    ua = rec.uv[A][f, i]
    held = rec.uv[B][f][seen[B]]
    out = []
    for p in pk:
        XA = triangulate(cams[1], (ua if A == 1 else p)[None], cams[0], (p if A == 1 else ua)[None])
        x, gap = XA[0][0], XA[1][0]
        if gap > gapmax:
            continue
        h = np.linalg.norm(held - p, axis=1).min() if len(held) else 99
        dpred = np.linalg.norm(x - pred[i]); dtrue = np.linalg.norm(p - t["uv"][f, B, i])
        # nearest other marker prediction
        oth = np.linalg.norm(pred - x, axis=1); oth[i] = np.inf
        j = int(np.nanargmin(oth))
        out.append((dpred, gap, h, dtrue, names[j], oth[j], p))
    out.sort(key=lambda r: r[0])
    print(f"frame {f}: A={A} ({'direct' if A else 'mirror'}) err A {np.linalg.norm(ua - t['uv'][f, A, i]):.1f}px; confirmed {both.sum()}; pred err {np.linalg.norm(pred[i] - triangulate(cams[1], t['uv'][f,1,i][None], cams[0], t['uv'][f,0,i][None])[0][0]):.2f} mm")
    for o in out[:6]:
        print(f"   cand d_pred {o[0]:5.2f} mm gap {o[1]:.2f} held-by-other {o[2]:5.1f}px  truth {o[3]:5.1f}px  nearest other pred {o[4]} {o[5]:.2f}")
