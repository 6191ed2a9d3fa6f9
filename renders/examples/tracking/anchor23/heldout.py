"""anchor23 through the library (branch anchor23, PYTHONPATH=/work/wt/anchor): main (anchor_step None) and
AF (anchor_step 5) in one process per set. usage: heldout.py OUT.jsonl SET..."""
import json, os, sys
sys.path.insert(0, "/work/main/renders/examples/tracking")
from trackscore import run_and_score   # noqa: E402
import lipgen.recon.anchor
from lipgen.recon.settings import ReconstructSettings
assert lipgen.recon.anchor.__file__.startswith("/work/wt/anchor/"), lipgen.recon.anchor.__file__
rec_dir = os.environ.get("REC_DIR", "rec_lib")
os.makedirs(rec_dir, exist_ok=True)
out = open(sys.argv[1], "a")
for path in sys.argv[2:]:
    name = os.path.basename(path.rstrip("/"))
    for var, step in (("main", None), ("AF", 5)):
        row = run_and_score(path, var, ReconstructSettings(anchor_step=step), os.path.join(rec_dir, f"{name}.{var}.npz"))
        if step is not None:
            from lipgen.recon.pipeline import Reconstruction
            row["anchor"] = Reconstruction.load(os.path.join(rec_dir, f"{name}.{var}.npz")).info["tracking_anchor"]
        print(json.dumps(row), file=out, flush=True)
