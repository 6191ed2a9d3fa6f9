import sys
sys.path.insert(0, "/work/main/renders/examples/tracking")
from trackscore import run_sets
from lipgen.recon.settings import ReconstructSettings
run_sets(sys.argv[1:], lambda var: ReconstructSettings())
