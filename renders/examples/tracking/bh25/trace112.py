"""Trace lower_mid (1) / lower_border_mid (11) on default 112 with BH: blob sightings, rejections, withdrawals."""
import sys, traceback
import numpy as np
from lipgen._threads import blas_threads
from lipgen.recon import track as T
from lipgen.recon.dots import DotSettings
from lipgen.recon.pipeline import reconstruct_dataset
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.tracks import TrackerSettings
WATCH = {int(x) for x in sys.argv[2].split(",")}
F0, F1 = int(sys.argv[3]), int(sys.argv[4])
count = {}
orig_step, orig_reject = T.MarkerTracker.step, T.MarkerTracker.reject
def step(self, image):
    out = orig_step(self, image)
    f = count[id(self)] = count.get(id(self), -1) + 1
    if F0 <= f <= F1:
        for m in WATCH:
            print(f"step t{id(self)%1000} f{f} m{m} st{out[1][m]} uv{np.round(out[0][m],1)} blob{self.blobbed[m]}")
    return out
def reject(self, markers):
    f = count.get(id(self), -1)
    idx = set(np.asarray(markers, dtype=int).ravel().tolist()) & WATCH
    if idx and F0 <= f <= F1:
        who = [fr.filename.split("/")[-1] + ":" + fr.name for fr in traceback.extract_stack()[-5:-1]]
        print(f"reject t{id(self)%1000} f{f} {sorted(idx)} st{[int(self._out[-1][1][i]) for i in idx]} by {who}")
    return orig_reject(self, markers)
T.MarkerTracker.step, T.MarkerTracker.reject = step, reject
bh = TrackerSettings(blobs=True, dots=DotSettings(blob_response="hessian"))
with blas_threads(1):
    reconstruct_dataset(sys.argv[1], settings=ReconstructSettings(tracker=bh, confirm_blobs=False))
