import sys, numpy as np, hashlib
from lipgen.dataset.settings import GenerateSettings
from lipgen.dataset.simulation import simulate_motion
m = simulate_motion(GenerateSettings.from_preset("hard", seed=int(sys.argv[1]), frames=12))
print(hashlib.sha256(np.ascontiguousarray(m.vertices).tobytes()).hexdigest()[:16])
