"""Where the visible sightings not accepted are, per marker: lost in a view (not found), found but not accepted."""
import sys, collections, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import Reconstruction
var = sys.argv[1]
for path in sys.argv[2:]:
    name = path.rstrip("/").split("/")[-1]
    ds = Dataset(path); names = list(ds.marks) + ["nose"]
    e = sighting_errors(load_truth(ds), Reconstruction.load(f"/work/reacq3/rec/{name}.{var}.npz"))
    c = collections.Counter(); tot = 0
    for v in e:
        x = e[v]; miss = x["truly"] & ~x["ok"]
        for f, p in zip(*np.nonzero(miss)):
            c[(names[p], "lost" if not x["got"][f, p] else "notacc")] += 1
        tot += int(miss.sum())
    per = collections.Counter()
    for (m, k), n in c.items(): per[m] += n
    print(name, "missing", tot, "| " + ", ".join(f"{m} {n} (lost {c[(m,'lost')]})" for m, n in per.most_common(6)))
