"""dup37 runner: this tree's reconstruct on each set (variant tag from argv[2]); saves the rec; a jsonl row.
usage: run.py OUT.jsonl TAG SET..."""
import sys, json, time
sys.path.insert(0, "/work/main/renders/examples/tracking")
from trackscore import score_row
from lipgen.dataset.layout import Dataset
from lipgen.recon.pipeline import reconstruct_dataset
from lipgen._threads import blas_threads
from lipgen.errors import DatasetError
out, tag = open(sys.argv[1], "a"), sys.argv[2]
for name in sys.argv[3:]:
    path = f"/work/sets/{name}"
    t = time.process_time()
    try:
        with blas_threads(1):
            rec = reconstruct_dataset(path)
    except (DatasetError, ValueError) as exc:
        print(json.dumps({"set": name, "variant": tag, "stopped": str(exc), "score": 0}), file=out, flush=True)
        continue
    rec.save(f"/work/b37/rec/{name}.{tag}.npz")
    extra = {"shared": rec.info.get("shared_dots")} if "shared_dots" in rec.info else {}
    print(json.dumps(score_row(Dataset(path), rec, name, tag, time.process_time() - t) | extra), file=out, flush=True)
