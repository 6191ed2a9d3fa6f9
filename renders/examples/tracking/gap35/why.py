"""Why truly visible dots are not detected in a first frame: response at truth vs thresholds.
usage: why.py SET FRAME..."""
import sys, numpy as np
from dataclasses import replace
from scipy import ndimage
sys.path.insert(0, "/work/b35")
from ffh import setup
from lipgen.recon.dots import ink_gray, dot_response, detect_dots, peak_roundness
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth

path = sys.argv[1]
g = setup(path); ds = Dataset(path); t = load_truth(ds); names = g["names"]
S = g["settings"].tracker.dots
print("sigma", S.sigma, "floor", S.min_contrast, "noise_k", S.noise_k, "sep", S.separation)
for k in map(int, sys.argv[2:]):
    views = g["rig"].split_views(np.asarray(ds[k].image))
    for v in range(2):
        gray = ink_gray(views[v]); R = dot_response(gray, S)
        med = np.median(R); mad = 1.4826 * np.median(np.abs(R - med))
        uv, st = detect_dots(views[v], S)
        size = 2 * int(np.floor(S.separation / 2)) + 1
        mx = ndimage.maximum_filter(R, size=size, mode="nearest")
        print(f"frame {k} view {v}: noise thr {med + S.noise_k*mad:.3f}, {len(uv)} dots; median strength {np.median(st):.3f}")
        for i, nm in enumerate(names):
            if not t["visible"][k, v, i]:
                continue
            c, r = t["uv"][k, v, i]
            d = np.linalg.norm(uv - [c, r], axis=1).min() if len(uv) else 99
            if d <= 1.5:
                continue
            r0, c0 = int(round(r)), int(round(c))
            win = R[r0-2:r0+3, c0-2:c0+3]
            j = np.unravel_index(np.argmax(win), win.shape); pr, pc = r0-2+j[0], c0-2+j[1]
            ismax = R[pr, pc] == mx[pr, pc]
            rnd, strong = peak_roundness(R, np.array([pr]), np.array([pc]))
            print(f"   {nm:20s} nearest dot {d:5.1f}px resp {R[pr,pc]:.3f} localmax {ismax} round {rnd[0]:.2f} gray {gray[r0,c0]:.2f}")
