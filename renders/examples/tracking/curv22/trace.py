"""Trace one marker through the tracker's events (step, acquire, reject, withdraw, take, forget, unlearn)
for main and reacquire_after=N. usage: python trace.py SET MARKER F0 F1 [N]"""
import sys, numpy as np, logging
logging.basicConfig(level=logging.WARNING)
logging.getLogger('lipgen.recon.motioncheck').setLevel(logging.DEBUG)
from lipgen._threads import blas_threads
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import reconstruct_dataset
import lipgen.recon.track as trackmod
import os, functools, lipgen.recon.motioncheck as mcmod, lipgen.recon.steps as stepsmod
pass
path, mark, f0, f1 = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
VAR = sys.argv[5]
ds = Dataset(path); names = list(ds.marks); p = names.index(mark)
MT = trackmod.MarkerTracker
trackers = []
orig_init = MT.__init__
def init(self, *a, **k):
    orig_init(self, *a, **k); self._vid = len(trackers) % 2; trackers.append(self)
MT.__init__ = init
def log(self, what):
    t = len(self._out) - 1
    if f0 <= t <= f1:
        uv, st, _ = self._out[-1]
        print(f"t={t} view={'VR'[self._vid]} {what}: st={st[p]} uv={np.round(uv[p],1)} gap={self.gap[p]} acq={self.acquired[p]}")
for name in ("step", "reject", "withdraw", "take", "forget", "unlearn"):
    orig = getattr(MT, name)
    def wrap(self, *a, _o=orig, _n=name, **k):
        if _n in ("reject", "withdraw"):
            idx = np.asarray(a[0]).ravel()
            if p not in idx: return _o(self, *a, **k)
        if _n in ("take", "forget", "unlearn") and a[0] != p: return _o(self, *a, **k)
        r = _o(self, *a, **k)
        import inspect
        fr = inspect.stack()[2]
        log(self, _n + f" from {fr.function}:{fr.filename.split('/')[-1]}:{fr.lineno}"); return r
    setattr(MT, name, wrap)
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.dots import DotSettings
settings = ReconstructSettings(tracker=trackmod.TrackerSettings(blobs=VAR in ("B","BH"), dots=DotSettings(blob_response="hessian" if VAR in ("E","BH") else "log")))
with blas_threads(1):
    rec = reconstruct_dataset(path, settings=settings)
tr = load_truth(ds)
truth_uv = None
e = sighting_errors(tr, rec)
for v, view in enumerate(("virtual", "real")):
    print(view, "err", np.round(e[view]["err"][f0:f1+1, p], 1).tolist())
    print(view, "ok ", e[view]["ok"][f0:f1+1, p].astype(int).tolist())
