import sys
sys.path.insert(0, "/work/main/renders/examples/tracking")
from trackscore import run_sets
from lipgen.recon.settings import ReconstructSettings
assert (sys.argv[2] in ("GF", "GF2")) == hasattr(ReconstructSettings(), "gap_fill"), "wrong tree"
run_sets(sys.argv[1:], lambda var: ReconstructSettings())
