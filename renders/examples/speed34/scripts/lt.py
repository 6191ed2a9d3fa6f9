"""Time the truth layer by part: python lt.py PRESET SEED FRAMES OUT.npz (SEED -1: the preset's default).
The factor count includes the cached K0 solver's calls (one per frame); count.py counts real factorisations."""
import sys, time, json
import numpy as np
from lipgen.dataset.settings import GenerateSettings
from lipgen.dataset.simulation import simulate_motion
import lipgen.subject.layer as L
preset, seed, frames, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
s = GenerateSettings.from_preset(preset, seed=seed, frames=frames) if seed >= 0 else GenerateSettings.from_preset(preset, frames=frames)
counts = {"factor": 0, "energy": 0, "solve": 0}
t_in = {"factor": 0.0, "energy": 0.0, "solve": 0.0}
energy = "_energy_grad" if hasattr(L.Layer, "_energy_grad") else "energy_grad"   # the solver's own call
orig_f, orig_e, orig_s = L.Layer._factor, getattr(L.Layer, energy), L.Layer.solve
def wrap(name, f):
    def g(*a, **k):
        counts[name] += 1; t = time.process_time(); r = f(*a, **k); t_in[name] += time.process_time() - t; return r
    return g
L.Layer._factor, L.Layer.solve = wrap("factor", orig_f), wrap("solve", orig_s)
setattr(L.Layer, energy, wrap("energy", orig_e))
c0 = time.process_time()
m = simulate_motion(s)
cpu = time.process_time() - c0
np.savez(out, V=m.vertices)
print(json.dumps({"preset": preset, "seed": seed, "frames": frames, "cpu_s": round(cpu, 2),
                  **{k + "_s": round(v, 2) for k, v in t_in.items()}, **counts}))
