"""Frame 0 after the first-frame stage (main): darkness of each wrong match's dot over the median of the right
matches' dots in that view, and the largest ratio among right matches."""
import sys, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from frame0 import frame0
from lipgen.recon.dots import detect_dots
for path in sys.argv[1:]:
    got, cfgs = frame0(path)
    ds = Dataset(path); t = load_truth(ds); names = list(ds.marks)
    halves = ds.rig.split_views(ds[0].image)
    for v in range(2):
        from dataclasses import replace
        uv, st = detect_dots(halves[v], replace(cfgs[v], min_contrast=0.03))
        def strength(p):
            d = np.linalg.norm(uv - p, axis=1); return st[d.argmin()] if d.min() < 1.0 else np.nan
        right, wrong = [], []
        for i in range(len(names)):
            if not np.isfinite(got[v][i]).all(): continue
            s = strength(got[v][i])
            (right if np.linalg.norm(got[v][i] - t['uv'][0, v, i]) <= 3 else wrong).append((names[i], s))
        med = np.nanmedian([s for _, s in right])
        print(path.split('/')[-1], 'view', v, 'right max ratio', round(float(np.nanmax([s for _, s in right]) / med), 2),
              'wrong', [(n, round(float(s / med), 2)) for n, s in wrong], flush=True)
