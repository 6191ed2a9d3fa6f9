"""First-frame stage on frames of a set, scored by the truth (development sets only).
usage: ffh.py OUT.jsonl STEP SET...   rows: set, frame, right/wrong/unmatched names, detect-miss names"""
import sys, os, json, numpy as np
import lipgen.recon.pipeline as pl
from lipgen.recon.firstpose import first_frame
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen._threads import blas_threads

class _Stop(Exception):
    pass

def setup(path):
    got = {}
    real = pl.track_raw_frames
    def grab(frames, rig, expected, settings, progress, **kw):
        got.update(rig=rig, expected=expected, settings=settings, **kw)
        raise _Stop
    pl.track_raw_frames = grab
    try:
        with blas_threads(1):
            pl.reconstruct_dataset(path)
    except _Stop:
        pass
    finally:
        pl.track_raw_frames = real
    return got

def score(path, frames, out):
    g = setup(path)
    ds = Dataset(path); names = g["names"]; t = load_truth(ds)
    for k in frames:
        views = g["rig"].split_views(np.asarray(ds[k].image))
        with blas_threads(1):
            inits, bad, found = first_frame(views, g["expected"], g["settings"], g["cameras"], g["rest_points"],
                                            names, g["layout_covariance"])
        uv = t["uv"][k]; vis = t["visible"][k]
        inits = np.stack(inits)
        err = np.linalg.norm(inits - uv, axis=2)
        seen = np.isfinite(err)
        det = np.stack([np.linalg.norm(found[v][:, None] - uv[v][None], axis=2).min(0) <= 1.5 if len(found[v])
                        else np.zeros(uv.shape[1], bool) for v in range(2)])
        right = (seen & (err <= 3)).all(0)
        wrong = (seen & (err > 3)).any(0)
        unm = ~seen.all(0) & ~wrong
        row = dict(set=os.path.basename(path.rstrip('/')), frame=int(k), right=int(right.sum()), wrong=int(wrong.sum()),
                   P=len(names), wrong_names=[names[i] for i in np.flatnonzero(wrong)],
                   unmatched=[names[i] for i in np.flatnonzero(unm)],
                   hidden=[names[i] for i in np.flatnonzero(~vis.all(0))],
                   undetected=[[names[i] for i in np.flatnonzero(vis[v] & ~det[v])] for v in range(2)])
        print(json.dumps(row), file=out, flush=True)

if __name__ == "__main__":
    out = open(sys.argv[1], "a"); step = int(sys.argv[2])
    for p in sys.argv[3:]:
        n = len(Dataset(p))
        score(p, range(0, n, step), out)
