"""Why a marker is never acquired: per frame, the dot nearest its true projection, its darkness over the view's
typical, and whether the layout acquisition wanted it. usage: python acqprobe.py SET MARKER F0 F1"""
import sys, numpy as np
from lipgen._threads import blas_threads
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen.recon.pipeline import reconstruct_dataset
import lipgen.recon.track as trackmod
path, mark, f0, f1 = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
ds = Dataset(path); names = list(ds.marks); p = names.index(mark); truth = load_truth(ds)
MT = trackmod.MarkerTracker; made = []
oi = MT.__init__
def init(self, *a, **k):
    oi(self, *a, **k); self._vid = len(made) % 2; made.append(self)
MT.__init__ = init
oa = MT._acquire
def acq(self, uv, status, dots, strength):
    t = len(self._out)   # this image's index (not appended yet)
    if f0 <= t <= f1:
        tp = truth["uv"][t, self._vid, p]
        d = np.linalg.norm(dots - tp, axis=1) if len(dots) else np.array([np.inf])
        j = int(d.argmin())
        seen = np.isin(status, (trackmod.TRACKED, trackmod.RECOVERED))
        typ = self.typical_strength(seen)
        print(f"t={t} view={'VR'[self._vid]} status={status[p]} gap={self.gap[p]} last={np.round(self.last[p],1)} "
              f"nearest dot {d[j]:.2f} px, strength {strength[j] if len(dots) else np.nan:.3f} / typical {typ:.3f} "
              f"twin={self.twins[p]} seen={seen.sum()}")
        from lipgen.recon.acquire import place_layout
        pos = place_layout(self.reference, uv, seen)[p]
        dd = np.sort(np.linalg.norm(dots - pos, axis=1))[:3] if len(dots) else []
        from lipgen.recon.acquire import acquire_layout
        cfg = self.cfg
        free = np.linalg.norm(dots[:, None] - uv[status != trackmod.LOST][None], axis=2).min(1, initial=np.inf) >= cfg.dots.separation / 2
        r = strength / typ
        free2 = free & (r >= cfg.min_strength_ratio) & (r <= (np.inf if cfg.max_strength_ratio is None else cfg.max_strength_ratio))
        wanted = (status == trackmod.LOST) & ~np.all(np.isfinite(self.last), axis=1) & ~self.twins
        m = acquire_layout(self.reference, uv, seen, wanted, dots, free2, cfg.acquire_gate, cfg.acquire_ratio)
        print(f"     free {free[j]} free2 {free2[j]} sep {cfg.dots.separation} wanted {np.flatnonzero(wanted)} match {m[p]} (dot {j})")
        print(f"     layout puts it {np.linalg.norm(pos - tp):.2f} px from its truth; nearest dots to that: {np.round(dd, 2)}")
    return oa(self, uv, status, dots, strength)
MT._acquire = acq
# LIMIT frames
from lipgen.dataset.layout import Dataset as _D
_o = _D.__iter__
def _it(self):
    for i, x in enumerate(_o(self)):
        if i > f1: return
        yield x
_D.__iter__ = _it
with blas_threads(1):
    try:
        reconstruct_dataset(path)
    except Exception as e:
        print('stopped', e)
