import sys, numpy as np, time
import lipgen.nrsfm.completion as C
from lipgen.nrsfm.validation import human_sequence
from lipgen.experiments.nrsfm_benchmarks import hide_points
from lipgen.nrsfm._tracks import check_tracks
from lipgen.nrsfm.engine import _normalise_scale
seq = human_sequence(int(sys.argv[1]), 80); F, P = seq.W.shape[0] // 2, seq.W.shape[1]
vis = hide_points(F, P, sys.argv[2]); W = seq.W.copy(); W[np.repeat(~vis, 2, axis=0)] = np.nan
tr = check_tracks(_normalise_scale(W, vis)[0], vis)
rows = np.arange(2 * F).reshape(F, 2)[0::2].ravel()
half = check_tracks(tr.W[rows], tr.mask[0::2])
rank = int(sys.argv[3])
lams = []
orig_solve = np.linalg.solve
st = C.SubspaceCompletion(half.W, half.mask, rank)
costs = []
orig = C._Frames.evaluate
def ev(self, N, Y=None):
    r = orig(self, N, Y)
    if Y is None: costs.append(r)
    return r
C._Frames.evaluate = ev
t = time.process_time(); st.run(100)
print("cpu", round(time.process_time() - t, 2), "steps", st.steps, "done", st.done, "first", st.first, "last", st.cost, "d", st.d, "hidden/frame max", int((~half.mask).sum(1).max()), "frames h>=d", int(((~half.mask).sum(1) >= st.d).sum()))
c = np.array(costs); best = np.minimum.accumulate(c); acc = np.r_[True, c[1:] < best[:-1]]
bs = c[acc]; g = -np.diff(np.r_[st.first, bs]) / np.r_[st.first, bs][:-1]
print("trials", len(c), "accepted", int(acc.sum()))
print([f"{x:.1e}" for x in g[::5]])
