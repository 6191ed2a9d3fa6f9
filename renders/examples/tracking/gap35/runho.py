"""Held-out rows: as runmain.py / rungf.py, a set whose reconstruction stops is recorded with score 0."""
import sys, json, os
sys.path.insert(0, "/work/main/renders/examples/tracking")
from trackscore import run_and_score
from lipgen.errors import DatasetError
from lipgen.recon.settings import ReconstructSettings
out, var = sys.argv[1], sys.argv[2]
assert (var == "GF") == hasattr(ReconstructSettings(), "gap_fill"), "wrong tree"
rec_dir = os.environ.get("REC_DIR", "rec")
with open(out, "a") as f:
    for path in sys.argv[3:]:
        name = os.path.basename(path.rstrip("/"))
        try:
            row = run_and_score(path, var, ReconstructSettings(), os.path.join(rec_dir, f"{name}.{var}.npz"))
        except DatasetError as e:
            row = dict(set=name, variant=var, stopped=str(e), score=0)
        print(json.dumps(row), file=f, flush=True)
