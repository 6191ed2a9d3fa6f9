"""Per marker: accepted within 3 px / over 3 px for two reconstructions of one set. usage: permark.py SET A.npz B.npz"""
import sys, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import Reconstruction
ds = Dataset(sys.argv[1]); names = list(ds.marks); truth = load_truth(ds)
res = []
for p in sys.argv[2:]:
    e = sighting_errors(truth, Reconstruction.load(p))
    w = sum((e[v]["ok"] & (e[v]["err"] <= 3)).sum(0) for v in e); o = sum((e[v]["ok"] & (e[v]["err"] > 3)).sum(0) for v in e)
    first_over = [int(np.flatnonzero((sum(e[v]["ok"] & (e[v]["err"] > 3) for v in e))[:, i])[0]) if o[i] else -1 for i in range(len(names))]
    res.append((w, o, first_over))
for i, n in enumerate(names):
    row = " | ".join(f"{r[0][i]:4d} {r[1][i]:3d} f{r[2][i]:3d}" for r in res)
    if len({(r[0][i], r[1][i]) for r in res}) > 1: print(f"{n:20s} {row}")
