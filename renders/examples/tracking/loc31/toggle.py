import sys, dataclasses, time
from lipgen.dataset.settings import GenerateSettings
from lipgen.dataset.presets import get_preset
from lipgen.dataset.generate import generate
seed, name = int(sys.argv[1]), sys.argv[2]
over = {}
for kv in sys.argv[3:]:
    k, v = kv.split("="); over[k] = eval(v)
cond = dataclasses.replace(get_preset("hard").image.conditions, **over)
s = GenerateSettings.from_preset("hard", seed=seed, frames=24, conditions=cond, calib_frames=5, lens_frames=4)
t = time.process_time()
generate(f"tog/{name}", s, workers=1, progress=False)
print(name, round(time.process_time() - t, 1), flush=True)
