import sys, json, time
sys.path.insert(0, "/work/main/renders/examples/tracking")
from trackscore import score_row
import lipgen
assert lipgen.__file__.startswith("/work/wt/m36"), lipgen.__file__
from lipgen.dataset.layout import Dataset
from lipgen.recon.pipeline import reconstruct_dataset
from lipgen._threads import blas_threads
from lipgen.errors import DatasetError
name = sys.argv[2]; out = open(sys.argv[1], "a"); path = f"/work/sets/{name}"
t = time.process_time()
try:
    with blas_threads(1):
        rec = reconstruct_dataset(path)
except (DatasetError, ValueError) as exc:
    print(json.dumps({"set": name, "variant": "main", "stopped": str(exc), "score": 0}), file=out, flush=True)
    sys.exit()
rec.save(f"/work/b36/ho/{name}.main.npz")
print(json.dumps(score_row(Dataset(path), rec, name, "main", time.process_time() - t)), file=out, flush=True)
