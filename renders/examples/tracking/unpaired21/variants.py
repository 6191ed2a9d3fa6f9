"""Variants in one process per set (one calibration). usage: python variants.py OUT.jsonl VARIANTS SET...
VARIANTS: comma list of parts joined by +: phys (motion_physics_prior), r1 (reacquire_after 1), fuM (forget_unpaired
M; needs candidate.patch), off (no motion check); none of them ("main"): both off. This experiment's baseline was
phys+r1 (the defaults since jaw21). Score per set: accepted within 3 px - 10 x accepted over 3 px (visible
sightings, both views)."""
import json, os, sys
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from trackscore import run_and_score   # noqa: E402  (renders/examples/tracking/trackscore.py)
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.track import TrackerSettings
out = open(sys.argv[1], "a")
variants = sys.argv[2].split(",")
for path in sys.argv[3:]:
    for var in variants:
        parts = set(var.split("+"))
        fu = [int(x[2:]) for x in parts if x.startswith("fu")]   # fuM needs candidate.patch applied
        settings = ReconstructSettings(motion_check="off" not in parts, motion_physics_prior="phys" in parts,
                                       **({"forget_unpaired": fu[0]} if fu else {}),
                                       tracker=TrackerSettings(reacquire_after=1 if "r1" in parts else None))
        row = run_and_score(path, var, settings,
                            f"/work/reacq4/rec/{os.path.basename(path.rstrip('/'))}.{var}.npz")
        print(json.dumps(row), file=out, flush=True)
