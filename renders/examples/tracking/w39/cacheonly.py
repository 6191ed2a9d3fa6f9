"""cacheonly.py SET... : the tracking of each set into the disk cache (main's settings); nothing is scored."""
import sys
sys.path.insert(0, "/work/b39")
import cached
import lipgen.recon.pipeline as pl
from lipgen._threads import blas_threads
for name in sys.argv[1:]:
    cached.use(name)
    with blas_threads(1):
        pl.reconstruct_dataset(f"/work/sets/{name}")
    print("cached", name, flush=True)
