"""faint28: one variant's rows, with the library's default settings, per set. The variant is the code on
PYTHONPATH: main (/work/main) or F (the faint worktree); the script checks which it got.
usage: PYTHONPATH=TREE run.py OUT.jsonl main|F SET..."""
import sys
sys.path.insert(0, "/work/main/renders/examples/tracking")
import lipgen.recon.blobs as blobs   # noqa: E402
from trackscore import run_sets   # noqa: E402
from lipgen.recon.settings import ReconstructSettings   # noqa: E402

assert (sys.argv[2] == "F") == hasattr(blobs, "ink_like"), (sys.argv[2], blobs.__file__)
run_sets(sys.argv[1:], lambda var: ReconstructSettings())
