import sys, collections, numpy as np
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.dataset.layout import Dataset
from lipgen.recon.pipeline import Reconstruction
by = collections.defaultdict(list); st = collections.Counter()
for arg in sys.argv[1:]:
    s, path = arg.split("=")
    tr = load_truth(Dataset(f"/work/sets/{s}")); rec = Reconstruction.load(path)
    e = sighting_errors(tr, rec)
    for v, view in enumerate(e):
        for f, p in zip(*np.nonzero(e[view]["ok"])):
            d = np.linalg.norm(tr["uv"][f, v] - rec.uv[v, f, p], axis=-1); d[p] = np.inf
            kind = "right" if e[view]["err"][f, p] <= 3 else ("neigh" if np.nanmin(d) < 1.5 else "lure")
            by[kind].append(rec.score[v, f, p]); st[(kind, int(rec.status[v, f, p]))] += 1
for k, v in by.items():
    v = np.array(v); print(k, len(v), "nan", int(np.isnan(v).sum()), np.nanpercentile(v, [5, 25, 50, 75]).round(3))
print(sorted(st.items()))
