"""Frame 0 after main's first-frame stage: per marker, matched in both views or one, right or wrong (3 px)."""
import sys, os, json, numpy as np, collections
import lipgen.recon.track as tr
from lipgen._threads import blas_threads
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen.recon.pipeline import reconstruct_dataset
class Stop(Exception): pass
got = []
step = tr.MarkerTracker.step
def first_step(self, *a, **k):
    r = step(self, *a, **k); got.append(self._out[-1][0].copy())
    if len(got) >= 2: raise Stop
    return r
tr.MarkerTracker.step = first_step
out = open(sys.argv[1], 'a')
for path in sys.argv[2:]:
    ds = Dataset(path); names = list(ds.marks); got.clear()
    try:
        with blas_threads(1): reconstruct_dataset(path)
    except Stop: pass
    t = load_truth(ds)
    err = np.linalg.norm(np.stack(got[:2]) - t['uv'][0], axis=2)
    seen = np.isfinite(err); vis = t['visible'][0] if t['visible'].ndim == 3 else t['visible'][0]
    rows = []
    for i, n in enumerate(names):
        s = seen[:, i]
        kind = 'both' if s.all() else 'one' if s.any() else 'none'
        ok = bool(np.all(err[s, i] <= 3)) if s.any() else None
        rows.append((n, kind, ok, [None if not seen[v, i] else round(float(err[v, i]), 1) for v in range(2)]))
    print(json.dumps(dict(set=os.path.basename(path.rstrip('/')), rows=rows)), file=out, flush=True)
