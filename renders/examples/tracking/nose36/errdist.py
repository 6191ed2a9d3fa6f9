import sys, numpy as np
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.dataset.layout import Dataset
from lipgen.recon.pipeline import Reconstruction
var = sys.argv[1]
allerr = {"virtual": [], "real": []}
for s in sys.argv[2:]:
    e = sighting_errors(load_truth(Dataset(f"/work/sets/{s}")), Reconstruction.load(f"/work/b35/rec/{s}.{var}.npz"))
    for k, v in e.items(): allerr[k] += list(v["err"][v["ok"]])
for k, v in allerr.items():
    v = np.array(v); n = len(v)
    rms = lambda x: np.sqrt(np.mean(x ** 2))
    print(k, n, "rms all %.3f" % rms(v), "rms<3 %.3f" % rms(v[v < 3]), "rms<1.5 %.3f" % rms(v[v < 1.5]), "rms<1 %.3f" % rms(v[v < 1]),
          "median %.3f" % np.median(v), "p90 %.3f p99 %.3f" % tuple(np.percentile(v, [90, 99])),
          "n>1 %d n>1.5 %d n>3 %d" % ((v > 1).sum(), (v > 1.5).sum(), (v > 3).sum()))
    # share of sum squares
    ss = v ** 2; print("  share of SS from >3: %.2f, 1.5-3: %.2f, 1-1.5: %.2f" % (ss[v > 3].sum() / ss.sum(), ss[(v > 1.5) & (v <= 3)].sum() / ss.sum(), ss[(v > 1) & (v <= 1.5)].sum() / ss.sum()))
