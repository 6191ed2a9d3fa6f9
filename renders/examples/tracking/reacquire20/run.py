"""Main against TrackerSettings(reacquire_after=N) on default sets, in one process per set (one calibration).

usage: python run.py OUT.jsonl SET... (SET: a dataset folder); candidates from env REACQ (default "1,5").
Score per set: accepted within 3 px - 10 x accepted over 3 px (visible sightings, both views).
"""
import json, os, sys, time
from dataclasses import replace
import numpy as np
from lipgen._threads import blas_threads
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.recon.pipeline import reconstruct_dataset
import lipgen.recon.track as trackmod
_TS = trackmod.TrackerSettings

cands = [None] + [int(x) for x in os.environ.get("REACQ", "1,5").split(",")]
out = open(sys.argv[1], "a")
for path in sys.argv[2:]:
    ds = Dataset(path)
    for n in cands:
        # settings=None, as lipgen reconstruct: the tracker's dot sigma is then fitted to the rig; the
        # tracker's settings class is wrapped to add the candidate's field
        def made(*a, _n=n, **kw):
            return _TS(*a, reacquire_after=_n, **kw)
        trackmod.TrackerSettings = made
        t = time.process_time()
        with blas_threads(1):
            rec = reconstruct_dataset(path)
        trackmod.TrackerSettings = _TS
        cpu = time.process_time() - t
        truth = load_truth(ds)   # read only after the tracking, to score
        e = sighting_errors(truth, rec)
        within = over = vis = acc = 0
        for view in ("virtual", "real"):
            x = e[view]
            vis += int(x["truly"].sum()); acc += int(x["ok"].sum())
            within += int((x["ok"] & (x["err"] <= 3)).sum()); over += int((x["ok"] & (x["err"] > 3)).sum())
        row = dict(set=os.path.basename(path.rstrip("/")), reacquire_after=n, visible=vis, accepted=acc,
                   share=round(100 * acc / vis, 2), within=within, over=over, score=within - 10 * over,
                   cpu=round(cpu, 1))
        print(json.dumps(row), file=out, flush=True)
