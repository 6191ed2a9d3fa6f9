"""Same set, same code, one BLAS kernel family or another (OPENBLAS_CORETYPE): does tracking change?"""
import sys, json, os, threadpoolctl
sys.path[:0] = ["/work/main/renders/examples/tracking"]
from trackscore import run_and_score
from lipgen.recon.settings import ReconstructSettings
name = sys.argv[1]
arch = sorted({i.get("architecture") for i in threadpoolctl.threadpool_info()})
row = run_and_score(f"/work/sets/{name}", "main", ReconstructSettings(), f"/work/b44/{name}.{os.environ.get('OPENBLAS_CORETYPE', 'auto')}.npz")
import threadpoolctl as t2
row["arch"] = sorted({i.get("architecture") for i in t2.threadpool_info()})
print(json.dumps(row), flush=True)
