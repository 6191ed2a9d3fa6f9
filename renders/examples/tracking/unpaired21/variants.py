"""Main against variants in one process per set (one calibration). usage: python variants.py OUT.jsonl VARIANTS SET...
VARIANTS: comma list of main, off (motion_check False), trust (MotionCheck trust_steps), r1 (reacquire_after 1),
trust+r1. Score per set: accepted within 3 px - 10 x accepted over 3 px (visible sightings, both views)."""
import json, os, sys, time, functools
from lipgen._threads import blas_threads
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import reconstruct_dataset
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.track import TrackerSettings
import lipgen.recon.motioncheck as mcmod
import lipgen.recon.steps as stepsmod
_MC = mcmod.MotionCheck
out = open(sys.argv[1], "a")
variants = sys.argv[2].split(",")
for path in sys.argv[3:]:
    ds = Dataset(path)
    for var in variants:
        parts = set(var.split("+"))
        pass
        fu = [int(x[2:]) for x in parts if x.startswith("fu")]
        settings = ReconstructSettings(motion_check="off" not in parts, motion_physics_prior="phys" in parts,
                                       forget_unpaired=fu[0] if fu else None,
                                       tracker=TrackerSettings(reacquire_after=1 if "r1" in parts else None))
        t = time.process_time()
        with blas_threads(1):
            rec = reconstruct_dataset(path, settings=settings)
        cpu = time.process_time() - t
        rec.save(f"/work/reacq4/rec/{os.path.basename(path.rstrip('/'))}.{var}.npz")
        truth = load_truth(ds)   # read only after the tracking, to score
        e = sighting_errors(truth, rec)
        within = over = vis = acc = 0
        for view in ("virtual", "real"):
            x = e[view]
            vis += int(x["truly"].sum()); acc += int(x["ok"].sum())
            within += int((x["ok"] & (x["err"] <= 3)).sum()); over += int((x["ok"] & (x["err"] > 3)).sum())
        row = dict(set=os.path.basename(path.rstrip("/")), variant=var, visible=vis, accepted=acc,
                   share=round(100 * acc / vis, 2), within=within, over=over, score=within - 10 * over,
                   cpu=round(cpu, 1))
        print(json.dumps(row), file=out, flush=True)
