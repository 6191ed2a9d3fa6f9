import sys, json, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import Reconstruction
tot = {}
for path in sys.argv[1:]:
    name = path.rstrip("/").split("/")[-1]
    ds = Dataset(path); t = load_truth(ds); rec = Reconstruction.load(f"/work/b35/rec/{name}.main.npz")
    e = sighting_errors(t, rec)
    vis = e["virtual"]["truly"] & e["real"]["truly"]
    miss = vis & ~e["virtual"]["ok"]
    got = np.stack([rec.status[v] != 3 for v in range(2)])
    err = np.stack([e[k]["err"] for k in ("virtual", "real")])
    c = {}
    for f, i in zip(*np.nonzero(miss)):
        g = tuple(got[:, f, i])
        if g == (True, True):
            k = "both seen, rejected"
        elif g == (False, False):
            k = "lost in both"
        else:
            v = 0 if g[0] else 1
            k = ("mirror only" if v == 0 else "direct only") + (" (right)" if err[v, f, i] <= 3 else " (wrong)")
        c[k] = c.get(k, 0) + 1
    print(name, int(miss.sum()), json.dumps(c))
    for k, v in c.items():
        tot[k] = tot.get(k, 0) + v
print("total", json.dumps(tot))
