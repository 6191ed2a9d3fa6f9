"""Same-process CPU of one reconstruction with the old tracking defaults (no blobs, no cross-check) against the
new defaults, calibration cached by a first warm-up run. usage: cost.py SET"""
import sys
import time
from dataclasses import replace

from lipgen._threads import blas_threads
from lipgen.recon.dots import DotSettings
from lipgen.recon.pipeline import reconstruct_dataset
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.tracks import TrackerSettings

old = ReconstructSettings(tracker=TrackerSettings(blobs=False, dots=DotSettings(blob_response="log")),
                          cross_check=False)
new = ReconstructSettings()
with blas_threads(1):
    reconstruct_dataset(sys.argv[1], settings=old)          # warm-up: the calibration is cached after it
    out = {}
    for name, s in (("old", old), ("new", new), ("old again", old)):
        t = time.process_time()
        reconstruct_dataset(sys.argv[1], settings=s)
        out[name] = time.process_time() - t
print({k: round(v, 1) for k, v in out.items()}, "ratio new/old", round(out["new"] / (0.5 * (out["old"] + out["old again"])), 2))
