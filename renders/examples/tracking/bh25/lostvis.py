"""Lost sightings on hard (main): how visible were their dots? Per view, the truth's dot_visible_fraction and
facing (cos of the angle between the dot's normal and the view ray) of lost vs accepted sightings."""
import sys, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import Reconstruction
VIEWS = ("virtual", "real")
acc = {v: [] for v in VIEWS}; lost = {v: [] for v in VIEWS}; names = None
for arg in sys.argv[1:]:
    setdir, rec = arg.split(":")
    ds = Dataset(setdir); tr = load_truth(ds); r = Reconstruction.load(rec); e = sighting_errors(tr, r)
    names = list(r.info["marker_names"]) + ["nose"]
    F = r.status.shape[1]
    truths = [ds.truth(i) for i in range(F)]
    dvf = np.stack([t["dot_visible_fraction"] for t in truths]); fac = np.stack([t["facing"] for t in truths])
    for vi, v in enumerate(VIEWS):
        t = e[v]["truly"]; ok = e[v]["ok"]; lo = t & ~e[v]["got"]
        for mask, out in ((ok, acc[v]), (lo, lost[v])):
            f, p = np.nonzero(mask)
            out.append(np.stack([dvf[f, vi, p], fac[f, vi, p], p], 1))
for v in VIEWS:
    a, l = np.vstack(acc[v]), np.vstack(lost[v])
    print(f"{v}: accepted {len(a)}, lost {len(l)}")
    for name, col in (("dot visible fraction", 0), ("facing", 1)):
        qa = np.percentile(a[:, col], [10, 50, 90]); ql = np.percentile(l[:, col], [10, 50, 90])
        print(f"  {name}: accepted p10/50/90 {np.round(qa, 2)}, lost {np.round(ql, 2)}")
    for thr in (0.5, 0.8):
        print(f"  share with visible fraction < {thr}: accepted {np.mean(a[:, 0] < thr):.3f}, lost {np.mean(l[:, 0] < thr):.3f}")
    for thr in (0.3, 0.5):
        print(f"  share with facing < {thr}: accepted {np.mean(a[:, 1] < thr):.3f}, lost {np.mean(l[:, 1] < thr):.3f}")
    side = [i for i, n in enumerate(names) if n.endswith("_left")]
    ls = np.isin(l[:, 2], side)
    print(f"  lost on *_left markers: {ls.sum()} of {len(l)}; their facing median {np.median(l[ls, 1]):.2f}, "
          f"others' {np.median(l[~ls, 1]):.2f}")
