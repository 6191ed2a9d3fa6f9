"""faint28's toy trace: tests/test_track.py's row drop (the bottom row drops 11 px at frame 6, markers 12 and 13 taken
back there) on seeds 0-7, with and without the curvature blobs: the (frame, marker) pairs lost after frame 6 and the
largest error (px). On main the blobs lose markers on seeds 0-3 and 6; with faint28.patch none.
usage: python rowdrop.py   (from the repository root)"""
import sys; sys.path.insert(0, "tests")
import numpy as np
from synthetic_images import background, frame, marker_paths
from lipgen.recon.track import MarkerTracker, TrackerSettings
SHAPE = (120, 160)
def _row_drop(seed, drop, n_frames=12, at=6):
    rng = np.random.default_rng(seed)
    base = background(SHAPE, rng)
    paths = marker_paths(n_frames, 15, rng, SHAPE, spacing=16, amplitude=2.0, own=0.5)
    paths[at:, 10:, 1] += np.asarray(drop, dtype=float)
    return rng, base, paths
for seed in range(8):
  for blobs in (False, True):
    rng, base, paths = _row_drop(seed, 11.0)
    tr = MarkerTracker(paths[0], TrackerSettings(blobs=blobs), reference_uv=paths[0])
    for t, p in enumerate(paths):
        tr.step(frame(base, p, rng))
        if t == 6: tr.reject([12, 13])
    tk = tr.tracks()
    lost = [(t, m) for t in range(12) for m in range(15) if not tk.visible[t, m] and t != 6]
    err = np.linalg.norm(tk.uv - paths, axis=2)
    print(seed, blobs, lost, np.nanmax(err).round(2))
