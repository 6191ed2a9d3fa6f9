"""xc27: the forward-backward cross-check (lipgen.recon.crosscheck) per set, with and without curvature blobs
(bh25's BHC2) and the fill. One process per set list; each variant's two tracking runs (forward, reversed) are
made once per blob setting and shared by the variants that differ only after tracking (drop vs drop + fill).
usage: run.py OUT.jsonl VARIANTS SET...   (PYTHONPATH: the worktree; variants main, X, XU, XB, XBU)"""
import sys
sys.path.insert(0, "/work/main/renders/examples/tracking")
import lipgen.recon.crosscheck as cc   # noqa: E402
import lipgen.recon.pipeline as pl   # noqa: E402
from trackscore import run_sets   # noqa: E402
from lipgen.recon.dots import DotSettings   # noqa: E402
from lipgen.recon.settings import ReconstructSettings   # noqa: E402
from lipgen.recon.tracks import TrackerSettings   # noqa: E402
assert cc.__file__.startswith("/work/wt/ff27/"), cc.__file__

memo, state = {}, {"base": None, "n": None}


def memoised(fn, direction):
    def wrapper(frame_at, n_frames, track, step, progress=None):
        head = frame_at(0)
        key = (state["base"], direction, n_frames, hash(head[::7, ::7].tobytes()))
        if key not in memo:
            memo.clear() if len(memo) > 8 else None
            memo[key] = fn(frame_at, n_frames, track, step, progress)
        return memo[key]
    return wrapper


pl.track_from_anchor = memoised(pl.track_from_anchor, "forward")
cc.track_from_anchor = memoised(cc.track_from_anchor, "reversed")


def settings_for(var):
    blobs = "B" in var
    state["base"] = "blobs" if blobs else "main"
    tracker = TrackerSettings(blobs=True, dots=DotSettings(blob_response="hessian")) if blobs else TrackerSettings()
    return ReconstructSettings(tracker=tracker, cross_check=var.startswith("X"), cross_check_fill=var.endswith("U"),
                               cross_check_arbitrate=var.endswith("A") or "K" in var, cross_check_keep="K" in var)


run_sets(sys.argv[1:], settings_for)
