"""Time the truth layer: python layer_time.py PRESET SEED FRAMES OUT.npz"""
import sys, time, resource, json
import numpy as np
from lipgen.dataset.settings import GenerateSettings
from lipgen.dataset.simulation import simulate_motion
import lipgen.subject.layer as L

preset, seed, frames, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
s = GenerateSettings.from_preset(preset, seed=seed, frames=frames)
counts = {"factor": 0, "tangent": 0, "energy": 0}
t_in = {"factor": 0.0, "tangent": 0.0}
orig_f, orig_t, orig_e = L.Layer._factor, L.Layer.tangent, L.Layer.energy_grad
def fac(self, x=None, active=None):
    counts["factor"] += x is not None
    t = time.process_time(); r = orig_f(self, x, active); t_in["factor"] += time.process_time() - t; return r
def tan(self, *a, **k):
    counts["tangent"] += 1; return orig_t(self, *a, **k)
def en(self, *a, **k):
    counts["energy"] += 1; return orig_e(self, *a, **k)
L.Layer._factor, L.Layer.tangent, L.Layer.energy_grad = fac, tan, en
c0 = time.process_time()
m = simulate_motion(s)
cpu = time.process_time() - c0
np.savez(out, V=m.vertices)
print(json.dumps({"preset": preset, "seed": seed, "frames": frames, "cpu_s": round(cpu, 2),
                  "factor_cpu_s": round(t_in["factor"], 2), **counts}))
