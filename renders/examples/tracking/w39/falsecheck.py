import sys, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, accepted_sightings
from lipgen.recon.pipeline import Reconstruction
for name in sys.argv[2:]:
    t = load_truth(Dataset(f"/work/sets/{name}"))
    out = []
    for var in ("main", sys.argv[1]):
        rec = Reconstruction.load(f"/work/b39/rec/{name}.{var}.npz")
        acc = accepted_sightings(rec)
        vis = t["visible"].transpose(1, 0, 2).astype(bool)
        out.append(f"{var}: accepted where truth hidden {int((acc & ~vis[0]).sum())}/{int((acc & ~vis[1]).sum())}")
    print(name, *out)
