"""The first-frame stage alone on every 5th frame: markers matched in both views (and how many of those the
truth puts within 3 px in both views: read after, for the analysis only). usage: probe.py OUT.jsonl SET..."""
import json, os, sys
import numpy as np
import lipgen.recon.pipeline as pl
from lipgen._threads import blas_threads
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth

real = pl.track_raw_frames
class Stop(Exception):
    pass
got = {}
def probe(frames, layout, expected, settings, progress=None, **kw):
    frames = list(frames)
    for k in range(0, len(frames), 5):
        v, r = real([frames[k]], layout, expected, settings, None, **kw)
        got[k] = (v.uv[0].copy(), r.uv[0].copy(), (v.visible[0] & r.visible[0]).copy())
    raise Stop
pl.track_raw_frames = probe
out = open(sys.argv[1], "a")
for path in sys.argv[2:]:
    got.clear()
    try:
        with blas_threads(1):
            pl.reconstruct_dataset(path)
    except Stop:
        pass
    truth = load_truth(Dataset(path))
    row = {"set": os.path.basename(path.rstrip("/")), "frames": {}}
    for k, (v, r, both) in got.items():
        tuv = truth["uv"][k]
        assert tuv.shape[0] == 2 and tuv.shape[1] >= v.shape[0], tuv.shape
        P = v.shape[0]
        right = (np.linalg.norm(v - tuv[0, :P], axis=-1) < 3) & (np.linalg.norm(r - tuv[1, :P], axis=-1) < 3)
        row["frames"][k] = {"matched": int(both.sum()), "right": int((both & right).sum()),
                            "wrong": int((both & ~right).sum())}
    print(json.dumps(row), file=out, flush=True)
