"""bh25: main (today's defaults), BH (curvature blobs, no confirmation: bh24's variant) and BHC / BHC2 (BH, blob
sightings withdrawn unless the other view sees the marker) per set, one process per set.
usage: run.py OUT.jsonl VARIANTS SET...   (PYTHONPATH: the worktree with bhc2.patch applied)
BHC and BHC2 have the same settings; they differ in the worktree's code: BHC's rows (dev.jsonl, probe128.jsonl)
ran with confirm_blobs called before the epipolar recovery in steps.py, BHC2's (dev2.jsonl, probe2.jsonl,
held.jsonl) after it, as in bhc2.patch."""
import sys
sys.path.insert(0, "/work/main/renders/examples/tracking")
from trackscore import run_sets   # noqa: E402
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

run_sets(sys.argv[1:], settings_for)
