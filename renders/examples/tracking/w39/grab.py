"""Capture extend_tracks' inputs for one set: grab.py SET -> /work/b39/grab_SET.pkl"""
import sys, pickle
sys.path.insert(0, "/work/b39")
import cached
import lipgen.recon.pipeline as pl
from lipgen.recon.settings import ReconstructSettings
from lipgen._threads import blas_threads
name = sys.argv[1]; cached.use(name)
orig = pl.extend_tracks
def grab(tracks, frame_at, cameras, accepted, reference, dots, floor, max_gap, gate, sure=None):
    with open(f"/work/b39/grab_{name}.pkl", "wb") as fh:
        pickle.dump(dict(tracks=tracks, cameras=cameras, accepted=accepted, reference=reference, dots=dots,
                         floor=floor, max_gap=max_gap, gate=gate, sure=sure), fh)
    return orig(tracks, frame_at, cameras, accepted, reference, dots, floor, max_gap, gate, sure=sure)
pl.extend_tracks = grab
with blas_threads(1):
    pl.reconstruct_dataset(f"/work/sets/{name}", settings=ReconstructSettings(walk_on=True))
