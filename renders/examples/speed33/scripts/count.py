import sys, json
import numpy as np
from lipgen.dataset.settings import GenerateSettings
from lipgen.dataset.simulation import simulate_motion
import lipgen.subject.layer as L
seed, frames = int(sys.argv[1]), int(sys.argv[2])
ev = {"evals": 0, "factorisations": 0}
name = "_energy_grad" if hasattr(L.Layer, "_energy_grad") else "energy_grad"
oe, of = getattr(L.Layer, name), L.Layer._factor
def en(*a, **k):
    ev["evals"] += 1; return oe(*a, **k)
def fa(self, x=None, active=None):
    ev["factorisations"] += x is not None; return of(self, x, active)
setattr(L.Layer, name, en); L.Layer._factor = fa
s = GenerateSettings.from_preset("hard", seed=seed, frames=frames) if seed >= 0 else GenerateSettings.from_preset("hard", frames=frames)
simulate_motion(s)
print(json.dumps(dict(seed=seed, frames=frames, **ev)))
