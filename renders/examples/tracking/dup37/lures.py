import sys, collections, numpy as np
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.dataset.layout import Dataset
from lipgen.recon.pipeline import Reconstruction
for arg in sys.argv[1:]:
    s, path = arg.split("=")
    tr = load_truth(Dataset(f"/work/sets/{s}")); rec = Reconstruction.load(path)
    names = list(rec.info["marker_names"]) + ["nose"]
    e = sighting_errors(tr, rec)
    for v, view in enumerate(e):
        err = e[view]["err"]; ok = e[view]["ok"]
        runs = collections.defaultdict(list)
        for f, p in zip(*np.nonzero(ok & (err > 3))):
            d = np.linalg.norm(tr["uv"][f, v] - rec.uv[v, f, p], axis=-1); d[p] = np.inf
            if np.nanmin(d) >= 1.5: runs[p].append((f, err[f, p], np.nanmin(d)))
        for p, r in runs.items():
            fr = [x[0] for x in r]
            print(s, view, names[p], "frames %d-%d n=%d" % (min(fr), max(fr), len(fr)), "err med %.1f max %.1f" % (np.median([x[1] for x in r]), max(x[1] for x in r)), "nearest other true %.1f" % np.median([x[2] for x in r]))
