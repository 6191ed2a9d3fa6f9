"""Frame 0 after the first-frame stage, greedy vs joint growth: markers right (<=3 px) in both views, wrong
(>3 px in a view), unmatched. usage: ff.py OUT.jsonl SET..."""
import sys, os, json, numpy as np, logging
import lipgen.recon.firstpose as fp
import lipgen.recon.track as tr
from lipgen._threads import blas_threads
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen.recon.pipeline import reconstruct_dataset
class Stop(Exception): pass
got = []
o = tr.MarkerTracker.step
def step(self, *a, **k):
    r = o(self, *a, **k)
    got.append(self._out[-1][0].copy())
    if len(got) >= 2: raise Stop
    return r
tr.MarkerTracker.step = step
out = open(sys.argv[1], 'a')
for path in sys.argv[2:]:
    ds = Dataset(path); names = list(ds.marks)
    for joint in (False, True):
        fp.FIRST_FRAME_CAP = joint; got.clear()
        try:
            with blas_threads(1):
                reconstruct_dataset(path)
        except Stop:
            pass
        t = load_truth(ds)
        vis = t['visible'][0] if 'visible' in t else None
        uv = np.stack(got[:2])          # (2, P, 2) virtual, real
        err = np.linalg.norm(uv - t['uv'][0], axis=2)
        seen = np.isfinite(err)
        right = (seen & (err <= 3)).all(0)
        wrong = (seen & (err > 3)).any(0)
        row = dict(set=os.path.basename(path.rstrip('/')), joint=joint, right=int(right.sum()), wrong=int(wrong.sum()),
                   wrong_names=[names[i] for i in np.flatnonzero(wrong)],
                   unmatched=[names[i] for i in np.flatnonzero(~seen.all(0) & ~wrong)])
        print(json.dumps(row), file=out, flush=True)
