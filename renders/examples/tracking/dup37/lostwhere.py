import sys, numpy as np
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.dataset.layout import Dataset
from lipgen.recon.pipeline import Reconstruction
for arg in sys.argv[1:]:
    s, path = arg.split("=")
    rec = Reconstruction.load(path); e = sighting_errors(load_truth(Dataset(f"/work/sets/{s}")), rec)
    names = list(rec.info["marker_names"]) + ["nose"]
    for v, view in enumerate(e):
        truly, got, ok = e[view]["truly"], e[view]["got"], e[view]["ok"]
        miss = (truly & ~ok).sum(0)
        print(s, view, "not accepted per marker:", {names[p]: int(miss[p]) for p in np.argsort(-miss)[:8] if miss[p]}, "lost in this view", int((truly & ~got).sum()), "got but not accepted", int((truly & got & ~ok).sum()))
