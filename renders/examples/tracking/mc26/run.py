"""mc26: main (today's defaults) and MC (the motion check spares the view whose sighting continues a track
when it would take a marker back in both views) per set. usage: run.py OUT.jsonl VARIANTS SET..."""
import json, os, sys
sys.path.insert(0, "/work/main/renders/examples/tracking")
from trackscore import run_and_score   # noqa: E402
import lipgen.recon.motioncheck as mc_mod
from lipgen.recon.settings import ReconstructSettings
assert mc_mod.__file__.startswith("/work/wt/mc26/"), mc_mod.__file__

def settings_for(var):
    return ReconstructSettings(motion_spare_continuing=(var == "MC"))

rec_dir = os.environ.get("REC_DIR", "rec")
os.makedirs(rec_dir, exist_ok=True)
out = open(sys.argv[1], "a")
for path in sys.argv[3:]:
    for var in sys.argv[2].split(","):
        name = os.path.basename(path.rstrip("/"))
        row = run_and_score(path, var, settings_for(var), os.path.join(rec_dir, f"{name}.{var}.npz"))
        print(json.dumps(row), file=out, flush=True)
