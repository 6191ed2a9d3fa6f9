"""Classify accepted sightings > 3 px: on another marker's dot (dup if that marker also holds it) or a lure."""
import sys, collections, numpy as np
from lipgen.evaluate.scoring import load_truth, sighting_errors, accepted_sightings
from lipgen.dataset.layout import Dataset
from lipgen.recon.pipeline import Reconstruction
tot = collections.Counter(); per = collections.Counter()
for arg in sys.argv[1:]:
    s, path = arg.split("=")
    tr = load_truth(Dataset(f"/work/sets/{s}")); rec = Reconstruction.load(path)
    names = list(rec.info.get("marker_names", [])) + ["nose"]
    e = sighting_errors(tr, rec); acc = accepted_sightings(rec)
    for v, view in enumerate(e):
        err = e[view]["err"]; ok = e[view]["ok"]
        F, P1 = err.shape
        for f, p in zip(*np.nonzero(ok & (err > 3))):
            d = np.linalg.norm(tr["uv"][f, v] - rec.uv[v, f, p], axis=-1); d[p] = np.inf
            j = int(np.nanargmin(d))
            if d[j] < 1.5:
                holds = acc[f, j] and np.linalg.norm(rec.uv[v, f, j] - rec.uv[v, f, p]) < 2
                kind = "dup" if holds else "neigh"
            else:
                kind = "lure"
            tot[kind] += 1
            per[(s, view, names[p] if p < len(names) else p, kind, names[j] if kind != "lure" else "")] += 1
print(tot)
for k, n in per.most_common(40): print(n, k)
