"""Which markers the split (P2) took back on each held-out set, and main's error (px) at those sightings
(truth read after the runs). usage: splits.py SET... (recs in /work/b43/rec)"""
import sys, numpy as np
from lipgen.recon.pipeline import Reconstruction
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.dataset.layout import Dataset
for s in sys.argv[1:]:
    r = Reconstruction.load(f"/work/b43/rec/{s}.P2.npz"); w = Reconstruction.load(f"/work/b43/rec/{s}.W.npz")
    names = r.info["marker_names"]
    ew = sighting_errors(load_truth(Dataset(f"/work/sets/{s}")), w)
    for g in r.info["split_runs"] or []:
        m = g["marker"]
        errs = {k: np.round(v["err"][g["taken"], m], 1).tolist() for k, v in ew.items()}
        print(s, names[m], "kept", len(g["kept"]), "taken", g["taken"], "main's err there", errs)
