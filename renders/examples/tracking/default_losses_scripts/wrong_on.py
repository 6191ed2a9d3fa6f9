import pickle, numpy as np, collections
from lipgen.dataset.layout import Dataset
from lipgen.recon.dots import DotSettings, ink_gray, dot_peaks
SETS = [1, 2, 4, 100, 101, 102, 103, 104]
c = collections.Counter()
for n in SETS:
    d = pickle.load(open(f"/work/diagdef/data_default_{n}.pkl", "rb")); ds = None
    for v in range(2):
        T = d["tuv"][:, v]
        bad = d["vis"][:, v] & d["acc"] & (d["err"][v] > 3)
        for f, k in zip(*np.nonzero(bad)):
            o = np.linalg.norm(np.delete(T[f], k, 0) - d["uv"][v, f, k], axis=1)
            if np.nanmin(o) <= 1.5: c["another marker's dot"] += 1; continue
            ds = ds or Dataset(f"/work/deftrack/sets/default_{n}")
            pk, s, rnd = dot_peaks(ink_gray(ds.rig.split_views(ds[f].image)[v]), DotSettings(sigma=d["sigma"]))
            dd = np.linalg.norm(pk - d["uv"][v, f, k], axis=1); j = dd.argmin()
            c["round peak (not a marker)" if dd[j] <= 1.5 and rnd[j] >= 0.3 else ("elongated peak" if dd[j] <= 1.5 else "no peak (blob/correlation)")] += 1
print(dict(c))
