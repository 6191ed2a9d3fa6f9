"""usage: run.py OUT.jsonl VARIANT[,VARIANT] SET...  (PYTHONPATH = the worktree; variants in VARIANTS)"""
import sys, json, time, os
sys.path.insert(0, "/work/main/renders/examples/tracking"); sys.path.insert(0, "/work/b39")
import cached
from trackscore import score_row
import lipgen.recon.pipeline as pl
from lipgen.dataset.layout import Dataset
from lipgen.recon.settings import ReconstructSettings
from lipgen._threads import blas_threads
from lipgen.errors import DatasetError
VARIANTS = {"main": {}}
try:
    from variants import VARIANTS as V2; VARIANTS.update(V2)
except ImportError:
    pass
out, tags = open(sys.argv[1], "a"), sys.argv[2].split(",")
for name in sys.argv[3:]:
    cached.use(name)
    path = f"/work/sets/{name}"
    for tag in tags:
        t = time.process_time()
        try:
            with blas_threads(1):
                rec = pl.reconstruct_dataset(path, settings=ReconstructSettings(**VARIANTS[tag]))
        except (DatasetError, ValueError) as exc:
            print(json.dumps({"set": name, "variant": tag, "stopped": str(exc), "score": 0}), file=out, flush=True)
            continue
        rec.save(f"/work/b39/rec/{name}.{tag}.npz")
        extra = {"gap_fill": rec.info.get("gap_fill"), "shared": len(rec.info.get("shared_dots") or [])}
        print(json.dumps(score_row(Dataset(path), rec, name, tag, time.process_time() - t) | extra), file=out, flush=True)
