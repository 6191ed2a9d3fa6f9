"""Audit the motion check's take-backs against the truth: usage python mcaudit.py OUT.jsonl SET..."""
import json, os, sys, time
import numpy as np
from lipgen._threads import blas_threads
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth, tracking_table
from lipgen.recon.pipeline import reconstruct_dataset
import lipgen.recon.motioncheck as mcmod
import lipgen.recon.steps as stepsmod
made = []
class MC(mcmod.MotionCheck):
    def __init__(self, *a, **k):
        super().__init__(*a, **k); made.append(self)
stepsmod.MotionCheck = MC
out = open(sys.argv[1], "a")
for path in sys.argv[2:]:
    made.clear()
    ds = Dataset(path); names = list(ds.marks)
    t = time.process_time()
    with blas_threads(1):
        rec = reconstruct_dataset(path)
    cpu = time.process_time() - t
    rec.save(f"/work/reacq3/rec/{os.path.basename(path)}.main.npz")
    truth = load_truth(ds)
    t = tracking_table(truth, rec)   # per view: accepted, rejected, lost, accepted over 3 px
    acc = sum(t[v]["accepted"] for v in t); over = sum(t[v]["wrong_over_3px"] for v in t)
    vis = sum(t[v]["accepted"] + t[v]["rejected"] + t[v]["lost"] for v in t); within = acc - over
    rows = []
    for (k, i, kind, vs, before) in made[0].changes:
        errs = [float(np.linalg.norm(before[v] - truth["uv"][k, v, i])) for v in range(2)]
        rows.append(dict(frame=int(k), marker=names[i], kind=kind, views=list(vs), err=[round(x, 2) for x in errs],
                         visible=[bool(truth["visible"][k, v, i]) for v in range(2)]))
    right = sum(1 for r in rows if max(r["err"]) <= 1.5)
    print(json.dumps(dict(set=os.path.basename(path), visible=vis, accepted=acc, within=within, over=over,
                          score=within - 10 * over, cpu=round(cpu, 1), changes=len(rows), right=right,
                          rows=rows)), file=out, flush=True)
