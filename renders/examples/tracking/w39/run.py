"""w39/s40 runner: run.py OUT.jsonl VARIANT[,VARIANT] SET...  (TREE = the lipgen tree, default /work/main;
MEMO_DIR = the memo's root, default /work/b39; VARIANTS_DIR = where variants.py is, default MEMO_DIR). Each set's
tracking comes from the disk memo (cached.py), so the variants differ only after it; each row is
trackscore.run_and_score's, the reconstruction saved to $MEMO_DIR/rec/SET.VARIANT.npz."""
import os, sys, json
ROOT = os.environ.get("MEMO_DIR", "/work/b39")
sys.path[:0] = [os.environ.get("VARIANTS_DIR", ROOT), os.environ.get("TREE", "/work/main"),
                "/work/main/renders/examples/tracking", os.path.dirname(os.path.abspath(__file__))]
import cached
from trackscore import run_and_score
from lipgen.recon.settings import ReconstructSettings
from variants import VARIANTS
VARIANTS = {"main": {}} | VARIANTS
with open(sys.argv[1], "a") as out:
    for name in sys.argv[3:]:
        cached.use(name)
        for tag in sys.argv[2].split(","):
            row = run_and_score(f"/work/sets/{name}", tag, ReconstructSettings(**VARIANTS[tag]),
                                f"{ROOT}/rec/{name}.{tag}.npz")
            print(json.dumps(row), file=out, flush=True)
