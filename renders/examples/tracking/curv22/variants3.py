"""Main against detector variants in one process per set (one calibration).
usage: python variants.py OUT.jsonl VARIANTS SET...   VARIANTS: comma list of
main; E (blob_response hessian: epipolar recovery only); B (tracker blobs, LoG); BH (tracker blobs, hessian).
Score per set: accepted within 3 px - 10 x accepted over 3 px (lipgen.evaluate.scoring.tracking_table)."""
import json, os, sys, time
from lipgen._threads import blas_threads
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import reconstruct_dataset
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.tracks import TrackerSettings
out = open(sys.argv[1], "a")
variants = sys.argv[2].split(",")
for path in sys.argv[3:]:
    ds = Dataset(path)
    for var in variants:
        import lipgen.recon.firstpose as fpmod; fpmod.FIRST_FRAME_CAP = var == "C"
        settings = ReconstructSettings()
        t = time.process_time()
        with blas_threads(1):
            rec = reconstruct_dataset(path, settings=settings)
        cpu = time.process_time() - t
        rec.save(f"/work/curv/rec/{os.path.basename(path.rstrip('/'))}.{var}.npz")
        e = sighting_errors(load_truth(ds), rec)   # the truth read only after the tracking, to score
        within = over = vis = acc = 0
        for view in ("virtual", "real"):
            x = e[view]
            vis += int(x["truly"].sum()); acc += int(x["ok"].sum())
            within += int((x["ok"] & (x["err"] <= 3)).sum()); over += int((x["ok"] & (x["err"] > 3)).sum())
        row = dict(set=os.path.basename(path.rstrip("/")), variant=var, visible=vis, accepted=acc,
                   share=round(100 * acc / vis, 2), within=within, over=over, score=within - 10 * over,
                   cpu=round(cpu, 1))
        print(json.dumps(row), file=out, flush=True)
