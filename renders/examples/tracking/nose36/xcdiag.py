"""Issue 15 dev diagnosis: final accepted sightings by how the two tracking runs (xc27) saw them,
right (<= 3 px) or wrong. usage: xcdiag.py OUT.jsonl SET..."""
import sys, json, os, numpy as np
import lipgen.recon.pipeline as pl
from lipgen.recon.crosscheck import cross_check as cc0
from lipgen.recon.tracks import seen as _seen
from lipgen.recon.pipeline import reconstruct_dataset
from lipgen.evaluate.scoring import load_truth, sighting_errors
from lipgen.dataset.layout import Dataset
from lipgen._threads import blas_threads
stash = {}
def cc(first, second, *a, **k):
    stash["first"], stash["second"] = first, second
    out = cc0(first, second, *a, **k); stash["tol"] = a[0]; return out
pl.cross_check = cc
out = open(sys.argv[1], "a")
for name in sys.argv[2:]:
    path = f"/work/sets/{name}"
    with blas_threads(1):
        rec = reconstruct_dataset(path)
    e = sighting_errors(load_truth(Dataset(path)), rec)
    first, second, tol = stash["first"], stash["second"], stash["tol"]
    sa = np.stack([_seen(t) for t in first]); sb = np.stack([_seen(t) for t in second])
    dist = np.stack([np.linalg.norm(a.uv - b.uv, axis=-1) for a, b in zip(first, second)])
    row = {"set": name}
    both_a = sa.all(0); both_b = sb.all(0); anyb = sb.any(0)
    with np.errstate(invalid="ignore"):
        agree2 = (dist <= tol).all(0)
    cls = np.full(both_a.shape, "other", object)
    cls[both_a & both_b & agree2] = "agree_both"
    cls[both_a & ~anyb] = "first_only"
    cls[both_a & anyb & ~both_b] = "second_partial"
    cls[both_a & both_b & ~agree2] = "disputed"
    cls[~both_a] = "not_first"
    for view in ("virtual", "real"):
        v = e[view]; ok = v["ok"]; err = v["err"]
        for c in ("agree_both", "first_only", "second_partial", "disputed", "not_first", "other"):
            m = ok & (cls == c)
            row[f"{view}_{c}"] = [int((m & (err <= 3)).sum()), int((m & (err > 3)).sum())]
    print(json.dumps(row), file=out, flush=True)
