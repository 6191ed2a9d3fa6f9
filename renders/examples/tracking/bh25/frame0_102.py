"""When does frame 0's sighting of a marker change? usage: frame0_102.py SET MARKER [main]. Logs each tracker's
frame-0 match of the marker and, before each later step, any change to it; BHC2's settings unless "main"."""
import sys
import numpy as np
from lipgen._threads import blas_threads
from lipgen.recon import track as T
from lipgen.recon.dots import DotSettings
from lipgen.recon.pipeline import reconstruct_dataset
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.tracks import TrackerSettings
M = int(sys.argv[2])
count, seen = {}, {}
orig_step = T.MarkerTracker.step
def step(self, image):
    f = count[id(self)] = count.get(id(self), -1) + 1
    if self._out:
        uv, st, _ = self._out[0]
        key = (id(self), f)
        now = (tuple(np.round(uv[M], 1)), int(st[M]))
        prev = seen.get(id(self))
        if prev != now:
            print(f"tracker {id(self) % 1000} before step {f}: frame0 m{M} {prev} -> {now}")
            seen[id(self)] = now
    out = orig_step(self, image)
    if f == 0:
        seen[id(self)] = (tuple(np.round(out[0][M], 1)), int(out[1][M]))
        print(f"tracker {id(self) % 1000} frame 0 step: m{M} {seen[id(self)]}")
    return out
T.MarkerTracker.step = step
bh = TrackerSettings(blobs=True, dots=DotSettings(blob_response="hessian"))
with blas_threads(1):
    rec = reconstruct_dataset(sys.argv[1], settings=(ReconstructSettings() if sys.argv[3:] == ["main"] else ReconstructSettings(tracker=bh, confirm_blobs=True)))
print("final frame 0:", rec.uv[:, 0, M], rec.status[:, 0, M])
