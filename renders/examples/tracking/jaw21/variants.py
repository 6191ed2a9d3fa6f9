"""Main against variants in one process per set (one calibration). usage: python variants.py OUT.jsonl VARIANTS SET...
VARIANTS: comma list of main, off (motion_check False), trust (MotionCheck trust_steps), r1 (reacquire_after 1),
trust+r1. Score per set: accepted within 3 px - 10 x accepted over 3 px (visible sightings, both views)."""
import json, os, sys, functools
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from trackscore import run_and_score   # noqa: E402  (renders/examples/tracking/trackscore.py)
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.track import TrackerSettings
import lipgen.recon.motioncheck as mcmod
import lipgen.recon.steps as stepsmod
_MC = mcmod.MotionCheck
out = open(sys.argv[1], "a")
variants = sys.argv[2].split(",")
for path in sys.argv[3:]:
    for var in variants:
        parts = set(var.split("+"))
        # trust_steps was built, measured and removed (jaw21.md): "trust" runs only on the commit that had it
        stepsmod.MotionCheck = functools.partial(_MC, trust_steps=True) if "trust" in parts else _MC
        settings = ReconstructSettings(motion_check="off" not in parts, motion_physics_prior="phys" in parts,
                                       tracker=TrackerSettings(reacquire_after=1 if "r1" in parts else None))
        row = run_and_score(path, var, settings,
                            f"/work/reacq3/rec/{os.path.basename(path.rstrip('/'))}.{var}.npz")
        print(json.dumps(row), file=out, flush=True)
