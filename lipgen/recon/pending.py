"""Acquisitions kept pending until the other view confirms or contradicts them.

A marker not seen yet is acquired in one view where the layout, registered to the markers seen,
puts it (:func:`lipgen.recon.acquire.acquire_layout`). An acquisition the other view does not see
was withdrawn at once (:func:`lipgen.recon.viewcheck.confirm_acquired`), though on ``hard``
frames most were right: on validation seed 9, 38 of 44 such withdrawals were within 1 px of the
truth, and the marker was then lost in both views until both acquired it in the same frame.

:class:`PendingAcquisitions` keeps such an acquisition in its view and follows it there (a
sighting in one view is never triangulated, so nothing is accepted from it alone). It is settled
on a later frame:

* the other view sees the marker and the rays meet (within the ray-gap limit): confirmed, and it
  continues as any track (the walk queue then carries the other view's early frames back);
* the other view sees it and the rays miss, the pending view loses it, or ``max_age`` frames pass
  unconfirmed: its sightings since the acquisition are erased
  (:meth:`lipgen.recon.track.MarkerTracker.forget`) and the marker is acquired afresh.
"""

from __future__ import annotations

import numpy as np

from lipgen.recon.track import LOST, MarkerTracker
from lipgen.rig.pinhole import triangulate

__all__ = ["PendingAcquisitions"]


class PendingAcquisitions:
    """One-view acquisitions waiting for the other view (see the module's description).

    Parameters
    ----------
    n_markers : int
        P.
    max_age : int
        Frames an acquisition may wait, at least 1.
    """

    def __init__(self, n_markers: int, max_age: int = 10):
        if int(max_age) < 1:
            raise ValueError(f"max_age must be at least 1, got {max_age!r}")
        self.since = np.full((2, int(n_markers)), -1, dtype=np.int64)   # image of the acquisition
        self.max_age = int(max_age)

    def step(self, trackers: list[MarkerTracker], cameras, max_gap: float) -> np.ndarray:
        """Settle the pending acquisitions on this image, then keep this image's new one-view ones.

        Call after both trackers' :meth:`~lipgen.recon.track.MarkerTracker.step` and before
        :func:`lipgen.recon.viewcheck.check_views`, which then sees the new pending ones as
        ordinary one-view sightings.

        Parameters
        ----------
        trackers : (virtual, real) MarkerTracker
        cameras : (virtual, real) PinholeCamera
        max_gap : float
            The ray-gap limit now, mm.

        Returns
        -------
        (2, P) bool
            The pending acquisitions erased on this image, per view.
        """
        now = len(trackers[0]._out) - 1
        forgot = np.zeros(self.since.shape, dtype=bool)
        for a in range(2):
            (uv_a, st_a, _), (uv_b, st_b, _) = trackers[a]._out[-1], trackers[1 - a]._out[-1]
            for k in np.flatnonzero(self.since[a] >= 0):
                if st_a[k] != LOST and st_b[k] != LOST:
                    g = triangulate(cameras[1], (uv_b if a == 0 else uv_a)[k][None],
                                    cameras[0], (uv_a if a == 0 else uv_b)[k][None])[1][0]
                    if g <= max_gap:
                        self.since[a, k] = -1        # confirmed
                        continue
                elif st_a[k] != LOST and now - self.since[a, k] < self.max_age:
                    continue                         # still waiting
                trackers[a].forget(k, int(self.since[a, k]))
                self.since[a, k] = -1
                forgot[a, k] = True
        for a in range(2):
            st_b = trackers[1 - a]._out[-1][1]
            new = trackers[a].acquired & (st_b == LOST) & (self.since[a] < 0)
            self.since[a, new] = now
            trackers[a].acquired[new] = False   # not an acquisition for the view check: a one-view sighting
        return forgot
