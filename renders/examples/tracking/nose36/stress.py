"""nose36 stress test: the tracker's nose removed; what the search fills. usage: stress.py OUT.jsonl SET..."""
import sys, json, numpy as np
import lipgen.recon.pipeline as pipeline
from lipgen.recon.association import LOST
from lipgen.recon.pipeline import reconstruct_dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.dataset.layout import Dataset
from lipgen._threads import blas_threads
track = pipeline.track_raw_frames
def without_nose(*a, **k):
    tracks = track(*a, **k)
    for t in tracks:
        t.uv[:, -1], t.status[:, -1], t.visible[:, -1] = np.nan, LOST, False
    return tracks
pipeline.track_raw_frames = without_nose
out = open(sys.argv[1], "a")
for name in sys.argv[2:]:
    path = f"/work/sets/{name}"
    with blas_threads(1):
        rec = reconstruct_dataset(path)
    e = sighting_errors(load_truth(Dataset(path)), rec)
    row = {"set": name, "nose": rec.info["nose"]}
    for view, v in e.items():
        err = v["err"][:, -1]; ok = v["ok"][:, -1]
        row[view] = {"accepted": int(ok.sum()), "truly": int(v["truly"][:, -1].sum()), "over3": int((err[ok] > 3).sum()),
                     "max_px": float(np.nanmax(err[ok])) if ok.any() else None, "rms_px": float(np.sqrt(np.mean(err[ok] ** 2))) if ok.any() else None}
    print(json.dumps(row), file=out, flush=True)
