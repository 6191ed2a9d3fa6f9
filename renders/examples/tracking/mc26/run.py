"""mc26: main (today's defaults) and MC (the motion check spares the view whose sighting continues a track
when it would take a marker back in both views) per set. usage: run.py OUT.jsonl VARIANTS SET..."""
import sys
sys.path.insert(0, "/work/main/renders/examples/tracking")
from trackscore import run_sets   # noqa: E402
import lipgen.recon.motioncheck as mc_mod
from lipgen.recon.settings import ReconstructSettings
assert mc_mod.__file__.startswith("/work/wt/mc26/"), mc_mod.__file__

def settings_for(var):
    return ReconstructSettings(motion_spare_continuing=(var == "MC"))

run_sets(sys.argv[1:], settings_for)
