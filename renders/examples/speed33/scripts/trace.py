import numpy as np, json
from lipgen.dataset.settings import GenerateSettings
from lipgen.dataset.simulation import simulate_motion
import lipgen.subject.layer as L
rows = []
orig_e, orig_f, orig_s = L.Layer.energy_grad, L.Layer._factor, L.Layer.solve
state = {"frame": -1}
def en(self, x, *a, **k):
    e, g = orig_e(self, x, *a, **k)
    free = ~self.fixed
    rows.append(("E", state["frame"], e, float(np.abs(g[free]).max())))
    return e, g
def fa(self, x=None, active=None):
    if x is not None: rows.append(("F", state["frame"]))
    return orig_f(self, x, active)
def so(self, *a, **k):
    state["frame"] += 1; return orig_s(self, *a, **k)
L.Layer.energy_grad, L.Layer._factor, L.Layer.solve = en, fa, so
simulate_motion(GenerateSettings.from_preset("hard", seed=5, frames=30))
for f in (11, 12, 20):
    print("frame", f)
    for r in rows:
        if r[1] == f:
            print("  ", r[0], *(f"{v:.6g}" for v in r[2:]))
