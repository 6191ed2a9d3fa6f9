"""Accepted sightings over 3 px on development sets: per marker and view, the frames, the error, and whose
true projection the sighting sits on (a label swap) -- truth read: development only.
usage: wrong.py REC_DIR VARIANT SET..."""
import sys
import numpy as np
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.dataset.layout import Dataset
from lipgen.recon.pipeline import Reconstruction

rec_dir, var = sys.argv[1], sys.argv[2]
for s in sys.argv[3:]:
    ds = Dataset(f"/work/sets/{s}")
    truth = load_truth(ds)
    rec = Reconstruction.load(f"{rec_dir}/{s}.{var}.npz")
    names = list(rec.info["marker_names"]) + ["nose"]
    errs = sighting_errors(truth, rec)
    for v, (view, e) in enumerate(errs.items()):
        bad = e["ok"] & (e["err"] > 3)
        for m in np.flatnonzero(bad.any(0)):
            fr = np.flatnonzero(bad[:, m])
            uv = rec.uv[v][fr, m]
            tu = truth["uv"][fr, v]                      # (n, P+1, 2)
            d = np.linalg.norm(tu - uv[:, None], axis=2)
            on = np.nanargmin(d, 1)
            lab = names[m] if names else m
            whose = {(names[o] if names else o) for o in on if d[list(on).index(o), o] < 2.0} if False else None
            near = [f"{(names[o] if names else o)}:{d[i, o]:.1f}" for i, o in enumerate(on)]
            print(s, view, lab, f"frames {fr.min()}-{fr.max()} ({len(fr)})", f"err {np.round(e['err'][fr, m].mean(), 1)}",
                  "nearest true:", sorted(set(n.split(':')[0] for n in near)),
                  f"d {np.round(np.median([float(n.split(':')[1]) for n in near]), 1)}")
