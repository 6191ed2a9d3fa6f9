"""For every accepted sighting: the distance (direct view) to the nearest detector peak that no accepted marker
holds, split by right (< 1.5 px in both views) and wrong (> 3 px in both) -- truth read; spent sets."""
import sys, os, pickle, numpy as np
from dataclasses import replace
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, accepted_sightings
from lipgen.recon.pipeline import Reconstruction, dot_sigma_px, lab_frame
from lipgen.recon.dots import as_gray, dot_peaks
from lipgen.recon.settings import ReconstructSettings
root, var, view = sys.argv[1], sys.argv[2], int(sys.argv[3])
for name in sys.argv[4:]:
    if not os.path.exists(f"{root}/cache/{name}.calib.pkl"):
        continue
    ds = Dataset(f"/work/sets/{name}"); t = load_truth(ds)
    rec = Reconstruction.load(f"{root}/rec/{name}.{var}.npz")
    acc = accepted_sightings(rec); tuv = np.moveaxis(t["uv"], 1, 0)
    err = np.linalg.norm(rec.uv - tuv, axis=-1)
    cal = pickle.load(open(f"{root}/cache/{name}.calib.pkl", "rb"))
    st = replace(ReconstructSettings().tracker.dots, sigma=dot_sigma_px(cal, lab_frame(cal), float(ds.settings.dot_diameter)))
    right, wrong = [], []
    for f in range(acc.shape[0]):
        uv, s, r = dot_peaks(as_gray(ds.rig.split_views(np.asarray(ds[f].image))[view]), st)
        held = rec.uv[view, f][acc[f]]
        free = uv[np.linalg.norm(uv[:, None] - held[None], axis=-1).min(axis=1) > 2.0]
        for k in np.flatnonzero(acc[f, :-1]):
            d = np.linalg.norm(free - rec.uv[view, f, k], axis=1).min() if len(free) else np.inf
            if (err[:, f, k] < 1.5).all(): right.append(d)
            elif (err[:, f, k] > 3).all(): wrong.append(d)
    right, wrong = np.array(right), np.array(wrong)
    row = [f"{name} view{view} right {len(right)} wrong {len(wrong)}"]
    for lim in (4, 6, 8, 10, 12):
        row.append(f"<={lim}px: right {np.mean(right <= lim)*100:.1f}% wrong {np.mean(wrong <= lim)*100 if len(wrong) else float('nan'):.0f}%")
    print(" | ".join(row), flush=True)
