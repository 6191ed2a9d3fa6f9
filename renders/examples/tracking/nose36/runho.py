"""nose36 held-out runner: N (this tree) on each set; main (047789d worktree, in a subprocess) where N's search ran.
usage: runho.py OUT.jsonl SET..."""
import sys, json, os, time, subprocess
sys.path.insert(0, "/work/main/renders/examples/tracking")
from trackscore import score_row
from lipgen.dataset.layout import Dataset
from lipgen.recon.pipeline import reconstruct_dataset
from lipgen._threads import blas_threads
from lipgen.errors import DatasetError
out = open(sys.argv[1], "a")
for name in sys.argv[2:]:
    path = f"/work/sets/{name}"
    t = time.process_time()
    try:
        with blas_threads(1):
            rec = reconstruct_dataset(path)
    except (DatasetError, ValueError) as exc:
        print(json.dumps({"set": name, "variant": "N", "stopped": str(exc), "score": 0}), file=out, flush=True)
        continue
    rec.save(f"/work/b36/ho/{name}.N.npz")
    row = score_row(Dataset(path), rec, name, "N", time.process_time() - t) | {"nose": rec.info["nose"]}
    print(json.dumps(row), file=out, flush=True)
    if rec.info["nose"]["searched"] or rec.info["nose"]["stand_in"]:
        subprocess.run([sys.executable, "/work/main/renders/examples/tracking/nose36/runmain.py", sys.argv[1], name],
                       env=dict(os.environ, PYTHONPATH="/work/wt/m36"), check=False)
    else:
        print(json.dumps({"set": name, "variant": "main", "same_as": "N (search did not run)", "score": row["score"]}), file=out, flush=True)
