"""Frame 0 as the tracker holds it after the first-frame stage (the curv22 scripts' shared hook)."""
import numpy as np
import lipgen.recon.track as track
from lipgen._threads import blas_threads
from lipgen.recon.pipeline import reconstruct_dataset


class _Stop(Exception):
    pass


def frame0(path):
    """((2, P, 2) float sightings of the virtual and real views at frame 0, NaN where none; the tracker's
    DotSettings per view). Runs the pipeline up to the tracker's first step in both views."""
    got, cfgs = [], []
    step = track.MarkerTracker.step

    def first_step(self, *a, **k):
        r = step(self, *a, **k)
        got.append(self._out[-1][0].copy()); cfgs.append(self.cfg.dots)
        if len(got) >= 2:
            raise _Stop
        return r

    track.MarkerTracker.step = first_step
    try:
        with blas_threads(1):
            reconstruct_dataset(path)
    except _Stop:
        pass
    finally:
        track.MarkerTracker.step = step
    return np.stack(got[:2]), cfgs[:2]
