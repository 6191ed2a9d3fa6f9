"""Instrumented reconstruct: save both tracking runs, the disputed mask and the judge's verdict (cross-check).
usage: xcrec.py SET..."""
import sys, numpy as np
import lipgen.recon.pipeline as pipeline
from lipgen._threads import blas_threads
saved = {}
orig_cc, orig_arb = pipeline.cross_check, pipeline.arbitrate
def arb(a, b, disputed, *args, **kw):
    out = orig_arb(a, b, disputed, *args, **kw); saved["verdict"] = np.asarray(out); saved["disputed"] = disputed; return out
def cc(first, second, *args, **kw):
    saved["first"] = np.stack([t.uv for t in first]); saved["second"] = np.stack([t.uv for t in second])
    saved["first_st"] = np.stack([t.status for t in first]); saved["second_st"] = np.stack([t.status for t in second])
    return orig_cc(first, second, *args, **kw)
pipeline.cross_check, pipeline.arbitrate = cc, arb
for name in sys.argv[1:]:
    saved.clear()
    with blas_threads(1):
        pipeline.reconstruct_dataset(f"/work/sets/{name}")
    np.savez(f"/work/b37/xc/{name}.npz", **saved)
