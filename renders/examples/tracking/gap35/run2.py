"""Second pass: track again with the subject's layout estimated from the first pass (main's reconstruction in
/work/b35/rec/SET.main.npz). usage: run2.py OUT.jsonl VARIANT SET...   VARIANT S2: the median of the normalised
markers (sublay.py); G3: generalised Procrustes of the accepted lab points (subjectlayout.py, as lipgen/recon/
subjectlayout.py on the branch s2, on PYTHONPATH)."""
import sys, os, json, time
import numpy as np
sys.path.insert(0, "/work/main/renders/examples/tracking"); sys.path.insert(0, "/work/b35")
import lipgen.recon.pipeline as pl
from trackscore import score_row
from lipgen.recon.pipeline import Reconstruction, reconstruct_dataset
from lipgen.recon.steps import expected_projections
from lipgen.dataset.layout import Dataset
from lipgen._threads import blas_threads

out = open(sys.argv[1], "a"); var = sys.argv[2]
real = pl.track_raw_frames
for path in sys.argv[3:]:
    name = os.path.basename(path.rstrip('/'))
    first = Reconstruction.load(f"/work/b35/rec/{name}.main.npz")
    if var == "G3":
        from lipgen.evaluate.scoring import accepted_sightings
        from lipgen.recon.subjectlayout import subject_layout
        seen_first = accepted_sightings(first)
    else:
        from sublay import subject_layout
    cache = {}

    def wrapped(frames, rig, expected, settings, progress, cameras=None, rest_points=None, **kw):
        if "rest" not in cache:
            cache["rest"] = (subject_layout(rest_points, first.lab_points, seen_first)[0] if var == "G3"
                             else subject_layout(rest_points, first)[0])
            cache["exp"] = expected_projections(cameras, cache["rest"])
        return real(frames, rig, cache["exp"], settings, progress, cameras=cameras, rest_points=cache["rest"], **kw)

    pl.track_raw_frames = wrapped
    t = time.process_time()
    with blas_threads(1):
        rec = reconstruct_dataset(path)
    cpu = time.process_time() - t
    pl.track_raw_frames = real
    rec.save(f"/work/b35/rec/{name}.{var}.npz")
    print(json.dumps(score_row(Dataset(path), rec, name, var, cpu)), file=out, flush=True)
