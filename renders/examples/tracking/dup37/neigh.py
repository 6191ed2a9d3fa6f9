import sys, collections, numpy as np
from lipgen.evaluate.scoring import load_truth, sighting_errors, accepted_sightings
from lipgen.dataset.layout import Dataset
from lipgen.recon.pipeline import Reconstruction
c = collections.Counter()
for arg in sys.argv[1:]:
    s, path = arg.split("=")
    tr = load_truth(Dataset(f"/work/sets/{s}")); rec = Reconstruction.load(path)
    e = sighting_errors(tr, rec); acc = accepted_sightings(rec)
    for v, view in enumerate(e):
        err = e[view]["err"]; ok = e[view]["ok"]
        for f, p in zip(*np.nonzero(ok & (err > 3))):
            d = np.linalg.norm(tr["uv"][f, v] - rec.uv[v, f, p], axis=-1); d[p] = np.inf
            j = int(np.nanargmin(d))
            if d[j] < 1.5 and not (acc[f, j] and np.linalg.norm(rec.uv[v, f, j] - rec.uv[v, f, p]) < 2):
                dj = np.linalg.norm(rec.uv[v, f, j] - rec.uv[v, f, p])
                c[(s, "status%d" % rec.status[v, f, j], "acc" if acc[f, j] else "notacc", "same" if dj < 2 else "elsewhere" if np.isfinite(dj) else "nan", "jvis" if tr["visible"][f, v, j] else "jhidden")] += 1
for k, n in c.most_common(): print(n, k)
