"""Save main and reacquire_after=N reconstructions of sets for diagnosis. usage: diag.py N SET..."""
import os, sys, time
from lipgen._threads import blas_threads
from lipgen.recon.pipeline import reconstruct_dataset
import lipgen.recon.track as trackmod
_TS = trackmod.TrackerSettings
n = int(sys.argv[1])
for path in sys.argv[2:]:
    name = os.path.basename(path.rstrip('/'))
    for tag, val in (("main", None), (f"r{n}", n)):
        out = f"/work/reacq2/{name}.{tag}.npz"
        if os.path.exists(out):
            continue
        def made(*a, _n=val, **kw):
            return _TS(*a, reacquire_after=_n, **kw)
        trackmod.TrackerSettings = made
        t = time.process_time()
        with blas_threads(1):
            rec = reconstruct_dataset(path)
        trackmod.TrackerSettings = _TS
        rec.save(out)
        print(name, tag, round(time.process_time() - t, 1), flush=True)
