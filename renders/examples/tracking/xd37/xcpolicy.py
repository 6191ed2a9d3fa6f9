"""Value of dispute policies per set, at the dispute stage (pair-level: +2 kept right, -20 kept wrong, 0 dropped).
P0 main: verdict 2 -> second, else first.  P1: undecided dropped.  P2: only verdict 2 kept (second), others dropped."""
import sys, numpy as np
from lipgen.evaluate.scoring import load_truth
from lipgen.dataset.layout import Dataset
tot = np.zeros(3)
for name in sys.argv[1:]:
    try: d = np.load(f"/work/b37/xc/{name}.npz")
    except FileNotFoundError: continue
    if "disputed" not in d: continue
    t = load_truth(Dataset(f"/work/sets/{name}")); tuv = t["uv"].transpose(1, 0, 2, 3)
    with np.errstate(invalid="ignore"):
        ea = np.nanmax(np.linalg.norm(d["first"] - tuv, axis=-1), axis=0); eb = np.nanmax(np.linalg.norm(d["second"] - tuv, axis=-1), axis=0)
    v = np.zeros(3)
    for f, p in zip(*np.nonzero(d["disputed"])):
        ver = int(d["verdict"][f, p]); va = 2 if ea[f, p] <= 3 else -20; vb = 2 if eb[f, p] <= 3 else -20
        v += [vb if ver == 2 else va, vb if ver == 2 else (va if ver == 1 else 0), vb if ver == 2 else 0]
    tot += v
    print(name, "P0 %d P1 %d P2 %d" % tuple(v))
print("total P0 %d P1 %d P2 %d" % tuple(tot))
