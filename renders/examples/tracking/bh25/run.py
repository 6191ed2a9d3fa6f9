"""bh25: main (today's defaults), BH (curvature blobs, no confirmation: bh24's variant) and BHC (BH, blob
sightings withdrawn unless the other view sees the marker) per set, one process per set.
usage: run.py OUT.jsonl VARIANTS SET..."""
import json, os, sys
sys.path.insert(0, "/work/main/renders/examples/tracking")
from trackscore import run_and_score   # noqa: E402
import lipgen.recon.dots as dots_mod
from lipgen.recon.dots import DotSettings
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.tracks import TrackerSettings
assert dots_mod.__file__.startswith("/work/wt/bh25/"), dots_mod.__file__

def settings_for(var):
    if var == "main":
        return ReconstructSettings()
    bh = TrackerSettings(blobs=True, dots=DotSettings(blob_response="hessian"))
    return ReconstructSettings(tracker=bh, confirm_blobs=var.startswith("BHC"))

rec_dir = os.environ.get("REC_DIR", "rec")
os.makedirs(rec_dir, exist_ok=True)
out = open(sys.argv[1], "a")
for path in sys.argv[3:]:
    for var in sys.argv[2].split(","):
        name = os.path.basename(path.rstrip("/"))
        row = run_and_score(path, var, settings_for(var), os.path.join(rec_dir, f"{name}.{var}.npz"))
        print(json.dumps(row), file=out, flush=True)
