import json, os, resource, shutil, sys, time
from lipgen.dataset.generate import generate
from lipgen.dataset.layout import GenerateSettings
import lipgen
print(lipgen.__file__)
physics = sys.argv[1]
def cpu():
    return sum(r.ru_utime + r.ru_stime for r in (resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)))
for k, frames in enumerate([6, 6, 36]):
    s = GenerateSettings.from_preset("hard", frames=frames, calib_frames=0, truth_physics=physics)
    folder = f"/tmp/gdrv-{k}"
    c0 = cpu()
    generate(folder, s, workers=1, progress=False)
    print(frames, physics, round(cpu() - c0, 2))
    shutil.rmtree(folder, ignore_errors=True)
