import sys, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import Reconstruction
H = np.zeros(8, int); runs = []
for path in sys.argv[1:]:
    name = path.rstrip("/").split("/")[-1]
    ds = Dataset(path); t = load_truth(ds); rec = Reconstruction.load(f"/work/b35/rec/{name}.main.npz")
    e = sighting_errors(t, rec)
    vis = e["virtual"]["truly"] & e["real"]["truly"]
    got = np.stack([rec.status[v] != 3 for v in range(2)])
    lost = vis & ~got[0] & ~got[1]
    for f, i in zip(*np.nonzero(lost)):
        H[min(f // 5, 7)] += 1
    for i in range(lost.shape[1]):
        d = np.diff(np.r_[0, lost[:, i].astype(int), 0]); s, e2 = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
        runs += [(name, i, a, b - a) for a, b in zip(s, e2)]
print("lost-in-both by frame bin of 5:", H.tolist())
L = np.array([r[3] for r in runs]); print("runs", len(L), "lengths: 1:", (L == 1).sum(), "2-3:", ((L >= 2) & (L <= 3)).sum(), "4-9:", ((L >= 4) & (L <= 9)).sum(), ">=10:", (L >= 10).sum(), "frames in runs>=10:", L[L >= 10].sum())
