"""w39 runner: run.py OUT.jsonl VARIANT[,VARIANT] SET...  (PYTHONPATH = the worktree; variants: main and
variants.py's). Each set's tracking comes from the disk cache (cached.py), so the variants differ only after
it; each row is trackscore.run_and_score's, the reconstruction saved to /work/b40/rec/SET.VARIANT.npz."""
import sys, json
sys.path.insert(0, "/work/main/renders/examples/tracking"); sys.path.insert(0, __import__("os").environ.get("TREE", "/work/main")); sys.path.insert(0, "/work/b40")
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
                                f"/work/b40/rec/{name}.{tag}.npz")
            print(json.dumps(row), file=out, flush=True)
