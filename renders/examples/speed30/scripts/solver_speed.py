import json, sys
from lipgen.bench.variance import _solver_speed
import lipgen
out = _solver_speed(False); out["tree"] = lipgen.__file__
print(json.dumps(out))
