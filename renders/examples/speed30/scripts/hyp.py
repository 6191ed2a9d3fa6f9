import numpy as np, time, pickle
import lipgen.recon.pointreg as pr
calls = []
orig = pr._hypotheses
def rec(dots, expected, gate):
    calls.append((dots.copy(), expected.copy(), gate)); return orig(dots, expected, gate)
pr._hypotheses = rec
from lipgen.recon.pipeline import reconstruct_dataset
import sys
reconstruct_dataset(sys.argv[1], rest="model")
pickle.dump(calls, open(sys.argv[2], "wb"))
print(len(calls), [len(c[0]) for c in calls][:20])
