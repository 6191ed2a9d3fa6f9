"""Issue 15's three targets per set from the saved reconstructions: accepted share of the visible sightings,
RMS px of the accepted ones, accepted over 3 px (both views pooled). usage: python targets.py VARIANT SET..."""
import sys, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import Reconstruction
var = sys.argv[1]
pool = {}
for path in sys.argv[2:]:
    name = path.rstrip("/").split("/")[-1]
    ds = Dataset(path); e = sighting_errors(load_truth(ds), Reconstruction.load(f"/work/reacq3/rec/{name}.{var}.npz"))
    err = np.concatenate([e[v]["err"][e[v]["ok"]] for v in e]); vis = sum(int(e[v]["truly"].sum()) for v in e)
    pre = name.split("_")[0]; pool.setdefault(pre, []).append((err, vis))
    print(f"{name:12s} {var:8s} accepted {100 * len(err) / vis:5.1f} %  RMS {np.sqrt(np.mean(err ** 2)):.2f} px  "
          f"median {np.median(err):.2f}  over 3 px {(err > 3).sum()}")
for pre, L in pool.items():
    err = np.concatenate([x for x, _ in L]); vis = sum(v for _, v in L)
    print(f"{pre:12s} {var:8s} pooled: accepted {100 * len(err) / vis:5.1f} %  RMS {np.sqrt(np.mean(err ** 2)):.2f} px  "
          f"without the over-3-px ones {np.sqrt(np.mean(err[err <= 3] ** 2)):.2f} px  over 3 px {(err > 3).sum()}")
