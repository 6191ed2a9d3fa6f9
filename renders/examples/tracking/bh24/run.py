"""bh24: main (today's defaults) and/or BH per set, one process per set. usage: run.py OUT.jsonl VARIANTS SET..."""
import sys
sys.path.insert(0, "/work/main/renders/examples/tracking")
from trackscore import run_sets   # noqa: E402
import lipgen.recon.dots as dots_mod
from lipgen.recon.dots import DotSettings
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.tracks import TrackerSettings
assert dots_mod.__file__.startswith("/work/wt/bh/"), dots_mod.__file__

def settings_for(var):
    if var == "main":
        return ReconstructSettings()
    return ReconstructSettings(tracker=TrackerSettings(blobs=True, dots=DotSettings(blob_response="hessian")))

run_sets(sys.argv[1:], settings_for)
