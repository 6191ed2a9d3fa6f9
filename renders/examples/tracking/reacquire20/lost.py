"""Where r1 loses within-3px sightings that main has: per marker/view counts and status in r1."""
import sys, numpy as np, collections
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import Reconstruction
name, path, tag = sys.argv[1:4]
ds = Dataset(path); tr = load_truth(ds); names = list(ds.marks)
R = {t: Reconstruction.load(f"/work/reacq2/{name}.{t}.npz") for t in ("main", tag)}
E = {t: sighting_errors(tr, r) for t, r in R.items()}
for v, view in enumerate(("virtual", "real")):
    gm = E["main"][view]["ok"] & (E["main"][view]["err"] <= 3)
    gc = E[tag][view]["ok"] & (E[tag][view]["err"] <= 3)
    lostc = gm & ~gc; gain = gc & ~gm
    c = collections.Counter(names[p] for f, p in zip(*np.nonzero(lostc)))
    g = collections.Counter(names[p] for f, p in zip(*np.nonzero(gain)))
    print(view, "lost", lostc.sum(), dict(c.most_common(6)), "gained", gain.sum(), dict(g.most_common(6)))
    for p in [names.index(k) for k, _ in c.most_common(3)]:
        fr = np.flatnonzero(lostc[:, p]); st = R[tag].status[v, fr, p]
        print("   ", names[p], "frames", fr.min(), "-", fr.max(), "r1 status", collections.Counter(st.tolist()),
              "r1 err", np.round(np.nanmedian(E[tag][view]["err"][fr, p]), 1))
