import sys, time, traceback, numpy as np
import lipgen.nrsfm.completion as C
from lipgen.nrsfm import reconstruct
from lipgen.nrsfm.validation import human_sequence
from lipgen.experiments.nrsfm_benchmarks import hide_points
seq = human_sequence(int(sys.argv[1]), 80); F, P = seq.W.shape[0] // 2, seq.W.shape[1]
vis = hide_points(F, P, sys.argv[2]); W = seq.W.copy(); W[np.repeat(~vis, 2, axis=0)] = np.nan
orig = C.SubspaceCompletion.run
def run(self, max_iter):
    s0 = self.steps; t = time.process_time(); orig(self, max_iter)
    st = [f.name for f in traceback.extract_stack()[-6:-1]]
    print(f"rank {self.mask.shape[1]-1-self.d} F {self.mask.shape[0]} cap {max_iter} steps {s0}->{self.steps} done {self.done} cpu {time.process_time()-t:.2f} via {'/'.join(st)}")
C.SubspaceCompletion.run = run
t = time.process_time(); rec = reconstruct(W, "auto", visible=vis); print("total", round(time.process_time() - t, 1), "k", rec.k)
