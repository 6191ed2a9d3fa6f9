"""Main's lost/rejected/wrong sightings on a set, classed by whether the image has any dot-like peak at the
truth (top-hat at the tracker's least floor, or the curvature pit detector over its noise floor).
usage: loss.py SET...  (reconstructions in /work/b35/rec/SET.main.npz)"""
import sys, json, numpy as np
from dataclasses import replace
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import Reconstruction
from lipgen.recon.dots import ink_gray, detect_dots, DotSettings
from lipgen.recon.blobs import _pit_peaks
from lipgen.recon.tracks import TrackerSettings

tot = {}
for path in sys.argv[1:]:
    name = path.rstrip("/").split("/")[-1]
    ds = Dataset(path); t = load_truth(ds); rec = Reconstruction.load(f"/work/b35/rec/{name}.main.npz")
    e = sighting_errors(t, rec)
    sig = rec.info["settings"]["tracker"]["dots"]["sigma"] if "settings" in rec.info else None
    S = DotSettings(sigma=sig)
    least = TrackerSettings().floor_min
    rows = {}
    for v, view in enumerate(("virtual", "real")):
        ev = e[view]
        miss = ev["truly"] & ~ev["ok"]
        wrong = ev["ok"] & (ev["err"] > 3)
        good = ev["ok"] & (ev["err"] <= 3)
        c = {"visible": int(ev["truly"].sum()), "good": int(good.sum()), "wrong": int(wrong.sum()),
             "miss": int(miss.sum()), "miss_nopeak": 0, "good_nopeak": 0}
        for f in range(len(ds)):
            need = miss[f] | good[f]
            if not need.any():
                continue
            img = ds.rig.split_views(np.asarray(ds[f].image))[v]
            uv1, _ = detect_dots(img, replace(S, min_contrast=least))
            r, cc = _pit_peaks(ink_gray(img), S)
            pk = np.vstack([uv1, np.column_stack([cc, r]).astype(float)])
            tu = t["uv"][f, v]
            near = np.linalg.norm(pk[:, None] - tu[None], axis=2).min(0) <= 1.5
            c["miss_nopeak"] += int((miss[f] & ~near).sum())
            c["good_nopeak"] += int((good[f] & ~near).sum())
        rows[view] = c
        for k, val in c.items():
            tot.setdefault(view, {}).setdefault(k, 0)
            tot[view][k] += val
    print(name, json.dumps(rows), flush=True)
print("total", json.dumps(tot))
