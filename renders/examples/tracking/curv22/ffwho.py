"""Frame 0 after the first-frame stage: for each wrong marker, whose true dot it took (nearest truth)."""
import sys, numpy as np
import lipgen.recon.grow as grow
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from frame0 import frame0
grow.JOINT = len(sys.argv) > 2 and sys.argv[2] == 'joint'
ds = Dataset(sys.argv[1]); names = list(ds.marks); t = load_truth(ds)
got, _ = frame0(sys.argv[1])
for v in range(2):
    uv = got[v]; tv = t['uv'][0, v]
    for i, n in enumerate(names):
        if not np.isfinite(uv[i]).all(): continue
        d = np.linalg.norm(tv - uv[i], axis=1); j = int(np.nanargmin(d))
        if d[i] > 3: print('view', v, n, '-> dot of', names[j], round(float(d[j]), 1), 'own truth', round(float(d[i]), 1))
