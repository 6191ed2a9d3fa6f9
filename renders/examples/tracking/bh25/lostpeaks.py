"""hard (main), virtual view: for each visible sighting the tracker lost, is there a detector peak at the truth?
Round (roundness >= min_roundness) or elongated, within 1.5 px; the detector at the reconstruction's own settings;
where neither, a blob peak (curvature pit or LoG, lipgen.recon.blobs; needs bh25/bhc2.patch) within 1.5 px."""
import sys, numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import Reconstruction
from dataclasses import replace
from lipgen.recon.blobs import blob_peaks
from lipgen.recon.dots import DotSettings, ink_gray, dot_peaks
counts = {"round": 0, "elongated": 0, "none": 0, "none_but_pit": 0, "none_but_log": 0}
by_angle = {}
V = int(sys.argv[1]); VN = ("virtual", "real")[V]
for arg in sys.argv[2:]:
    setdir, rec = arg.split(":")
    ds = Dataset(setdir); tr = load_truth(ds); r = Reconstruction.load(rec); e = sighting_errors(tr, r)
    d = dict(r.info["settings"]["tracker"]["dots"]); d.pop("blob_response", None)
    cfg = DotSettings(**d)
    lost = e[VN]["truly"] & ~e[VN]["got"]
    for f in np.flatnonzero(lost.any(1)):
        img = ds.rig.split_views(ds[f].image)[V]
        gray = ink_gray(img)
        pk, s, rnd = dot_peaks(gray, cfg)
        blobs = {k: blob_peaks(gray, replace(cfg, blob_response=k))[0] for k in ("hessian", "log")}
        t = tr["uv"][f, V]
        for p in np.flatnonzero(lost[f]):
            dist = np.linalg.norm(pk - t[p], axis=1) if len(pk) else np.array([np.inf])
            near = dist <= 1.5
            if (near & (rnd >= cfg.min_roundness)).any():
                counts["round"] += 1
            elif near.any():
                counts["elongated"] += 1
            else:
                counts["none"] += 1
                for kind, key in (("hessian", "none_but_pit"), ("log", "none_but_log")):
                    b = blobs[kind]
                    if len(b) and np.linalg.norm(b - t[p], axis=1).min() <= 1.5:
                        counts[key] += 1
print(VN, counts)
