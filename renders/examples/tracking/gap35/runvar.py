import sys
sys.path.insert(0, "/work/main/renders/examples/tracking")
import lipgen.recon.oneview as ov
from trackscore import run_sets
from lipgen.recon.settings import ReconstructSettings
assert (sys.argv[2] in ("AR", "AR2")) == hasattr(ov, "ALONG_RAY_SD") and (sys.argv[2] == "AR2") == hasattr(ov, "AR2"), ov.__file__
run_sets(sys.argv[1:], lambda var: ReconstructSettings())
