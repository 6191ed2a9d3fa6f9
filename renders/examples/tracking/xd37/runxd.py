"""xd37 runner: baseline (defaults) and XD (cross_check_arbitrate=False, cross_check_keep=False) on each set,
in one process (one calibration). usage: runxd.py OUT.jsonl SET..."""
import sys, json, time
sys.path.insert(0, "/work/main/renders/examples/tracking")
from trackscore import score_row
from lipgen.dataset.layout import Dataset
from lipgen.recon.pipeline import reconstruct_dataset
from lipgen.recon.settings import ReconstructSettings
from lipgen._threads import blas_threads
from lipgen.errors import DatasetError
out = open(sys.argv[1], "a")
VARIANTS = {"base": ReconstructSettings(), "XD": ReconstructSettings(cross_check_arbitrate=False, cross_check_keep=False)}
for name in sys.argv[2:]:
    path = f"/work/sets/{name}"
    for tag, settings in VARIANTS.items():
        t = time.process_time()
        try:
            with blas_threads(1):
                rec = reconstruct_dataset(path, settings=settings)
        except (DatasetError, ValueError) as exc:
            print(json.dumps({"set": name, "variant": tag, "stopped": str(exc), "score": 0}), file=out, flush=True)
            continue
        rec.save(f"/work/b37/rec/{name}.{tag}.npz")
        print(json.dumps(score_row(Dataset(path), rec, name, tag, time.process_time() - t) | {"cross_check": rec.info["cross_check"]}), file=out, flush=True)
