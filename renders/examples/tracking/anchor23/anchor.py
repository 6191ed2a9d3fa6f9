"""Candidate 'anchor': track from the frame whose first-frame stage matches the most markers in both views,
forward to the end and backward to frame 0, against main in the same process (one calibration).

usage: python anchor.py OUT.jsonl VARIANTS SET...   VARIANTS: comma list of main, A5, A10 (anchor step)"""
import json, os, sys, time
import numpy as np
sys.path.insert(0, "/work/main/renders/examples/tracking")
from trackscore import run_and_score   # noqa: E402
import lipgen.recon.pipeline as pl
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.tracks import Tracks

real = pl.track_raw_frames
STEP = {"A5": 5, "A10": 10}
state = {}


def _cat(parts):
    keys = ("uv", "visible", "status", "score")
    out = {k: np.concatenate([getattr(p, k) for p in parts]) for k in keys}
    rej = [p.rejected for p in parts]
    out["rejected"] = None if any(r is None for r in rej) else np.concatenate(rej)
    return Tracks(**out)


def _rev(t):
    return Tracks(uv=t.uv[::-1], visible=t.visible[::-1], status=t.status[::-1], score=t.score[::-1],
                  rejected=None if t.rejected is None else t.rejected[::-1])


def bidir(frames, layout, expected, settings=ReconstructSettings(), progress=None, **kw):
    frames = list(frames)
    n = len(frames)
    t0 = time.process_time()
    if state["variant"] == "AF":   # the first of frames 0, 5, 10, ... with every mark matched in both views
        best = (None, 0)
        for k in range(0, n, 5):
            v, r = real([frames[k]], layout, expected, settings, None, **kw)
            both = int((v.visible[0] & r.visible[0]).sum())
            if both == expected.shape[1]:
                best = (both, k)
                break
    else:
        step = STEP[state["variant"]]
        best = None
        for k in range(0, n, step):
            v, r = real([frames[k]], layout, expected, settings, None, **kw)
            both = int((v.visible[0] & r.visible[0]).sum())
            if best is None or both > best[0]:
                best = (both, k)
    k = best[1]
    state["anchor"], state["anchor_cpu"], state["matched"] = k, time.process_time() - t0, best[0]
    fwd = real(frames[k:], layout, expected, settings, None, **kw)
    if k == 0:
        return fwd
    back = real(frames[k::-1], layout, expected, settings, None, **kw)
    return tuple(_cat([_slice(_rev(b), 0, k), f]) for b, f in zip(back, fwd))


def _slice(t, a, b):
    return Tracks(uv=t.uv[a:b], visible=t.visible[a:b], status=t.status[a:b], score=t.score[a:b],
                  rejected=None if t.rejected is None else t.rejected[a:b])


rec_dir = os.environ.get("REC_DIR", "rec")
os.makedirs(rec_dir, exist_ok=True)
out = open(sys.argv[1], "a")
for path in sys.argv[3:]:
    for var in sys.argv[2].split(","):
        state.clear()
        state["variant"] = var
        pl.track_raw_frames = real if var == "main" else bidir
        name = os.path.basename(path.rstrip("/"))
        row = run_and_score(path, var, ReconstructSettings(), os.path.join(rec_dir, f"{name}.{var}.npz"))
        row.update({k: v for k, v in state.items() if k != "variant"})
        print(json.dumps(row), file=out, flush=True)
