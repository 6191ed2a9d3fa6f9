"""Per frame: is there a round top-hat dot (at the tracker's sigma, floor 0.05) within 1.5 px of the marker's true
projection in each view, and the nearest other marker's truth distance. usage: detnear.py SET MARKER"""
import sys, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen.recon.dots import DotSettings, detect_dots
from lipgen.recon.pipeline import dot_sigma_px
ds = Dataset(sys.argv[1]); names = list(ds.marks); t = load_truth(ds); i = names.index(sys.argv[2])
sig = float(sys.argv[3]) if len(sys.argv) > 3 else 1.27
for v in range(2):
    s = ''; strengths = []
    for f in range(0, len(ds), max(1, len(ds) // 40)):
        if not t['visible'][f, v, i]: s += '-'; continue
        uv, st = detect_dots(ds.rig.split_views(ds[f].image)[v], DotSettings(sigma=sig, min_contrast=0.05))
        d = np.linalg.norm(uv - t['uv'][f, v, i], axis=1) if len(uv) else np.array([99.0])
        j = int(d.argmin()); s += 'D' if d[j] <= 1.5 else ('n' if d[j] <= 3 else '.')
        if d[j] <= 1.5: strengths.append(st[j])
    others = np.linalg.norm(np.delete(t['uv'][0, v], i, axis=0) - t['uv'][0, v, i], axis=1)
    print('view', v, s, 'median strength', np.round(np.median(strengths), 3) if strengths else None,
          'nearest other mark at frame 0', names[[k for k in range(len(names)) if k != i][int(np.nanargmin(others))]], np.round(np.nanmin(others), 1))
