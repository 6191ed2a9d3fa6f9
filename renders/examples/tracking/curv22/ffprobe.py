"""First-frame registration of default 108/114: aligned layout vs dots near bow_dip / upper_mid."""
import sys, numpy as np
import lipgen.recon.pointreg as pr
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
path = sys.argv[1]
ds = Dataset(path); names = list(ds.marks); t = load_truth(ds)
calls = []
orig = pr.register_nonrigid
def rn(dots, expected, gate, iterations=12, robust=False):
    match, aligned = orig(dots, expected, gate, iterations, robust)
    calls.append((dots.copy(), expected.copy(), match.copy(), aligned.copy(), gate))
    return match, aligned
pr.register_nonrigid = rn
orig_ra = pr.register_points
from lipgen.recon.pipeline import reconstruct_dataset
import lipgen.recon.steps as st
class Stop(Exception): pass
orig_track = st.MarkerTracker.step if hasattr(st, 'MarkerTracker') else None
import lipgen.recon.track as tr
n = [0]
o = tr.MarkerTracker.step
def step(self, *a, **k):
    n[0] += 1
    if n[0] > 2: raise Stop
    return o(self, *a, **k)
tr.MarkerTracker.step = step
try:
    reconstruct_dataset(path)
except Stop:
    pass
ib, iu = names.index('bow_dip'), names.index('upper_mid')
for c, (dots, exp, match, al, gate) in enumerate(calls):
    v = 0 if len(exp) == len(names) else -1
    print(f"call {c} P={len(exp)} gate={gate:.1f} dots={len(dots)}")
    for i in (ib, iu):
        d = np.linalg.norm(dots - al[i], axis=1); o2 = np.argsort(d)[:3]
        print(f"  {names[i]:10s} exp {np.round(exp[i],1)} aligned {np.round(al[i],1)} match {match[i]} "
              f"dots near {[(int(j), np.round(dots[j],1).tolist(), round(float(d[j]),1)) for j in o2]}")
for v in range(2):
    print('truth view', v, 'bow_dip', np.round(t['uv'][0, v, ib], 1), 'upper_mid', np.round(t['uv'][0, v, iu], 1))
