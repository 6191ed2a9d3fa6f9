"""Re-checking the markers' identities on later frames, and re-tracking a marker whose identity changes.

The first frame's matches are checked in 3-D against the marker layout
(:func:`lipgen.recon.firstframe.check_layout`), but where the mouth is open in that frame the
layout at rest predicts the lip corners millimetres off, and a lure 9 px along the epipolar line
of the marker's own dot passes (an 8-frame H.264 clip of seed 5: the direct view's
``corner_left``, 7 accepted sightings about 9 px off). Later frames contradict it: the same check
run on frame 1 on finds the marker's own pair of dots and the lure's point out of place.

A single frame's verdict is not trusted: on ``default`` seed 8 (validation) the check proposes a
wrong pair for a right marker in 4 isolated frames of 60. So :class:`IdentityCheck` runs the
check on every frame's sightings and acts only when it proposes a new dot for the same marker
in the same view(s) on ``frames`` frames in a row, each new dot within the recovery gate of the
last. Then the marker is re-tracked from that frame: forward, the tracker takes the new dot
(:meth:`lipgen.recon.track.MarkerTracker.take`); backward, the frames before are walked back
from it (:func:`lipgen.recon.backfill.walk_back`), each new sighting confirmed by the other view,
replacing the old one; where the walk stops (the dot not found as a round dot, or not
confirmed), the old identity's earlier sightings are taken back (rejected, so the per-marker
account counts them), not left accepted in silence. The change is logged with the marker's
name, the frames rewritten and the sightings taken back.
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen.recon.backfill import _point, walk_back
from lipgen.recon.dots import ink_gray
from lipgen.recon.firstframe import check_layout
from lipgen.recon.jumps import StepLimit
from lipgen.recon.track import LOST, MarkerTracker
from lipgen.rig.camera import VIEWS

__all__ = ["IdentityCheck"]

log = logging.getLogger(__name__)


class IdentityCheck:
    """Runs the 3-D layout check on every frame and re-tracks a marker it contradicts in a row.

    Parameters
    ----------
    rest_points : (P, 3) float
        The markers at rest in the frame of the cameras, mm.
    frames : int
        Frames in a row the check must propose the same marker's new dot before it is taken.
    covariance : (3P, 3P) float, optional
        The layout check's physics prior (:func:`~lipgen.recon.firstframe.check_layout`).
    """

    def __init__(self, rest_points, frames: int = 3, covariance=None):
        self.rest = np.asarray(rest_points, dtype=float)
        if self.rest.ndim != 2 or self.rest.shape[1] != 3:
            raise ValueError(f"rest_points must have shape (P, 3), got {self.rest.shape}")
        if int(frames) < 1:
            raise ValueError(f"frames must be at least 1, got {frames!r}")
        self.frames = int(frames)
        self.covariance = covariance
        P = len(self.rest)
        self.run = np.zeros((2, P), dtype=np.int64)
        self.prev = np.full((2, P, 2), np.nan)
        # Each re-identification: (frame, marker, views, frames rewritten per view).
        self.changes: list[tuple[int, int, tuple[int, ...], np.ndarray]] = []

    def step(self, trackers: list[MarkerTracker], views, cameras, max_gap: float,
             last3d: np.ndarray | None = None, steps: StepLimit | None = None, names=None,
             since: np.ndarray | None = None) -> np.ndarray:
        """Check the current frame; re-track the markers contradicted ``frames`` frames in a row.

        Parameters
        ----------
        trackers : (virtual, real) MarkerTracker
            After the current image's step and view checks.
        views : (virtual, real) images
            The current split images (for the new dots' templates).
        cameras : (virtual, real) PinholeCamera
        max_gap : float
            Largest distance between the two rays, mm.
        last3d : (P, 3) float, optional
            Each marker's last accepted point; a re-tracked marker's is set to its new point.
        steps : StepLimit, optional
            The 3-D step limits, for the walk back.
        names : sequence of str, optional
            Marker names, for the log.
        since : (P,) float, optional
            Frames since ``last3d`` (after this frame's view checks); a re-tracked marker's is set to 1,
            as the view checks set a kept marker's.

        Returns
        -------
        (2, P) bool
            The sightings changed in this frame, per view.
        """
        P = len(self.rest)
        now = [np.where((tr._out[-1][1] != LOST)[:, None], tr._out[-1][0], np.nan) for tr in trackers]
        dots = [tr.dot_history[-1][0] for tr in trackers]
        out, changed = check_layout(now, dots, cameras, self.rest, max_gap, covariance=self.covariance)
        new = np.stack([np.where(changed[v][:, None], out[v], np.nan) for v in range(2)])   # (2, P, 2)
        prop = changed & np.all(np.isfinite(new), axis=2)
        gate = np.array([tr.cfg.recovery_gate for tr in trackers])[:, None]
        near = np.linalg.norm(new - self.prev, axis=2) <= gate
        self.run = np.where(prop, np.where(near, self.run + 1, 1), 0)
        self.prev = np.where(prop[..., None], new, np.nan)
        fire = self.run >= self.frames
        fire &= (fire | ~prop).all(0)[None]           # every view the check changes, together
        took = np.zeros((2, P), dtype=bool)
        k = len(trackers[0]._out) - 1
        limits = None if steps is None else steps.limits(pooled=True)
        for i in np.flatnonzero(fire.any(0)):
            vs = tuple(int(v) for v in np.flatnonzero(fire[:, i]))
            for v in vs:
                d, s = trackers[v].dot_history[-1]
                trackers[v].take(i, new[v, i], ink_gray(views[v]),
                                 float(s[np.argmin(np.linalg.norm(d - new[v, i], axis=1))]))
                took[v, i] = True
            pt = _point(cameras, trackers[0]._out[-1][0][i], trackers[1]._out[-1][0][i])
            if last3d is not None and np.all(np.isfinite(pt)):
                last3d[i] = pt
                if since is not None:
                    # a marker the view checks did not keep (a twin they saw lost, resolved after them)
                    # has an old count: its point is this frame's now
                    since[i] = 1
            filled = walk_back(trackers, cameras, i, vs, k, max_gap, limits)[0]
            dropped = [_take_back_run(trackers[v], i, k - 1 - int(filled[v])) for v in range(2)]
            self.changes.append((k, int(i), vs, filled))
            self.run[:, i] = 0
            self.prev[:, i] = np.nan
            log.warning("frame %d: %s re-identified in the %s view(s) (the 3-D layout contradicted its dot "
                        "%d frames in a row); re-tracked from there, %s frame(s) before rewritten, %s "
                        "earlier sighting(s) on the old dot taken back", k,
                        i if names is None else names[i], " and ".join(VIEWS[v] for v in vs), self.frames,
                        " / ".join(str(int(filled[v])) for v in vs), " / ".join(str(dropped[v]) for v in vs))
        return took


def _take_back_run(tracker: MarkerTracker, i: int, start: int) -> int:
    """Take back marker ``i``'s sightings from frame ``start`` back to where its run of sightings
    began (the old identity's, which the walk back could not replace); returns how many."""
    n = 0
    for t in range(start, -1, -1):
        uv, status, _ = tracker._out[t]
        if status[i] == LOST:
            break
        uv[i], status[i] = np.nan, LOST
        tracker._rejected[t][i] = True
        n += 1
    return n
