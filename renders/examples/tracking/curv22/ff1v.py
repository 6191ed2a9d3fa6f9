"""Frame 0 after main's first-frame stage: per marker, matched in both views or one, right or wrong (3 px)."""
import sys, os, json, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from frame0 import frame0
out = open(sys.argv[1], 'a')
for path in sys.argv[2:]:
    ds = Dataset(path); names = list(ds.marks)
    got, _ = frame0(path)
    t = load_truth(ds)
    err = np.linalg.norm(got - t['uv'][0], axis=2)
    seen = np.isfinite(err)
    rows = []
    for i, n in enumerate(names):
        s = seen[:, i]
        kind = 'both' if s.all() else 'one' if s.any() else 'none'
        ok = bool(np.all(err[s, i] <= 3)) if s.any() else None
        rows.append((n, kind, ok, [None if not seen[v, i] else round(float(err[v, i]), 1) for v in range(2)]))
    print(json.dumps(dict(set=os.path.basename(path.rstrip('/')), rows=rows)), file=out, flush=True)
