"""g38 runner: one tracking per set (memoised), then main / GF / GFA reconstructions from it; a jsonl row each.
usage: run.py OUT.jsonl VARIANTS(comma) SET...   (run from /work/wt/g38)"""
import sys, json, time
sys.path.insert(0, "/work/main/renders/examples/tracking")
from trackscore import score_row
import lipgen.recon.pipeline as pl
from lipgen.dataset.layout import Dataset
from lipgen.recon.settings import ReconstructSettings
from lipgen._threads import blas_threads
from lipgen.errors import DatasetError
assert pl.__file__.startswith("/work/wt/g38"), pl.__file__
VARIANTS = {"main": dict(gap_fill=None), "GF": dict(gap_fill=3, gap_fill_sure=False),
            "GFA": dict(gap_fill=3, gap_fill_sure=True)}
memo = {}
def memoised(fn, key):
    def run(*a, **k):
        if (CUR, key) not in memo:
            memo[(CUR, key)] = fn(*a, **k)
        return memo[(CUR, key)]
    return run
pl.track_from_anchor = memoised(pl.track_from_anchor, "first")
pl.reversed_run = memoised(pl.reversed_run, "second")
out, tags = open(sys.argv[1], "a"), sys.argv[2].split(",")
for name in sys.argv[3:]:
    CUR = name
    path = f"/work/sets/{name}"
    for tag in tags:
        t = time.process_time()
        try:
            with blas_threads(1):
                rec = pl.reconstruct_dataset(path, settings=ReconstructSettings(**VARIANTS[tag]))
        except (DatasetError, ValueError) as exc:
            print(json.dumps({"set": name, "variant": tag, "stopped": str(exc), "score": 0}), file=out, flush=True)
            continue
        rec.save(f"/work/b38/rec/{name}.{tag}.npz")
        extra = {"gap_fill": rec.info.get("gap_fill"), "shared": len(rec.info.get("shared_dots") or [])}
        print(json.dumps(score_row(Dataset(path), rec, name, tag, time.process_time() - t) | extra), file=out,
              flush=True)
