"""Checks between the two views of the rig, every frame of :func:`lipgen.recon.steps.track_raw_frames`.

A wrong dot in one view is found by the other: the two rays of a right pair meet (the ray gap,
:class:`lipgen.recon.raygap.RayGapLimit`), another marker's ray may explain the dot better
(an identity mix-up along an epipolar line), its 3-D step may be a jump
(:class:`lipgen.recon.jumps.StepLimit`), and a marker acquired for the first time in a view
(:meth:`lipgen.recon.track.MarkerTracker.step`, ``TrackerSettings.acquire_gate``) stands only when
the other view sees it too, with rays that meet.
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen.recon.jumps import StepLimit
from lipgen.recon.motioncheck import frame_points
from lipgen.recon.movedref import moved_reference
from lipgen.recon.raygap import RayGapLimit
from lipgen.recon.track import LOST, MarkerTracker
from lipgen.rig.pinhole import triangulate

__all__ = ["check_views", "confirm_acquired", "confirm_blobs"]

log = logging.getLogger(__name__)


def confirm_acquired(trackers: list[MarkerTracker], cameras, max_gap: float) -> np.ndarray:
    """Withdraw this image's acquisitions the other view does not confirm.

    Parameters
    ----------
    trackers : (virtual, real) MarkerTracker
        After this image's :meth:`~lipgen.recon.track.MarkerTracker.step`.
    cameras : (virtual, real) PinholeCamera
    max_gap : float
        Largest distance between the two rays, mm.

    Returns
    -------
    (2, P) bool
        The acquisitions withdrawn, per view. An acquisition stands when the other view sees the
        marker and the rays pass within ``max_gap``; if both views acquired it and the rays miss,
        both are withdrawn; if one view continues a track, only the acquisition is.
    """
    (uv0, st0, _), (uv1, st1, _) = trackers[0]._out[-1], trackers[1]._out[-1]
    acq = np.stack([trackers[0].acquired, trackers[1].acquired])
    out = np.zeros_like(acq)
    if not acq.any():
        return out
    out[0] = acq[0] & (st1 == LOST)
    out[1] = acq[1] & (st0 == LOST)
    pair = acq.any(0) & (st0 != LOST) & (st1 != LOST)
    if pair.any():
        gap = np.full(len(pair), np.nan)
        gap[pair] = triangulate(cameras[1], uv1[pair], cameras[0], uv0[pair])[1]
        miss = pair & (gap > max_gap)
        out |= acq & miss[None]
    for v in range(2):
        trackers[v].withdraw(np.flatnonzero(out[v]))
    return out


def confirm_blobs(trackers: list[MarkerTracker]) -> np.ndarray:
    """Withdraw this image's blob sightings (:attr:`~lipgen.recon.track.MarkerTracker.blobbed`) of
    markers the other view does not see.

    A blob is a dot the detector could not resolve, and a fold's shadow or a neighbour's half-hidden
    dot looks like one; alone in one view it is a guess. Where the other view sees the marker, the
    ray-gap check of :func:`check_views` judges the pair. Returns the (2, P) bool withdrawn.
    """
    seen = np.stack([tr._out[-1][1] != LOST for tr in trackers])
    out = np.stack([tr.blobbed for tr in trackers]) & ~seen[::-1]
    for v in range(2):
        trackers[v].withdraw(np.flatnonzero(out[v]))
    return out


def check_views(trackers: list[MarkerTracker], cameras, gap_limit: RayGapLimit | float,
                 last3d: np.ndarray | None = None, steps: StepLimit | None = None,
                 since: np.ndarray | None = None, names=None, reference_age: int | None = None) -> None:
    """Take back sightings whose two rays pass farther apart than ``gap_limit`` (a wrong dot in a view).

    Acquisitions of markers not seen before (:attr:`~lipgen.recon.track.MarkerTracker.acquired`)
    are checked first: one the other view does not see, or whose rays pass farther apart than the
    limit, is withdrawn (:meth:`~lipgen.recon.track.MarkerTracker.withdraw`, not counted as a
    rejected sighting), so an acquisition stands only where both views agree on it.

    ``gap_limit`` is a :class:`~lipgen.recon.raygap.RayGapLimit` (it learns from the gaps of the
    sightings kept) or a fixed limit in mm. With ``last3d (P, 3)`` (each marker's last accepted
    point, updated in place), sightings another marker's ray explains better are taken back too
    (:func:`_reject_ambiguous`). With ``steps`` and ``since (P,)`` (frames since ``last3d``,
    updated in place), a sighting whose 3-D step is a jump (:class:`~lipgen.recon.jumps.StepLimit`)
    is taken back in both views. With ``reference_age`` n and ``since``, the identity check judges
    against the last points at least n images old moved to this image with their neighbours
    (:func:`lipgen.recon.movedref.moved_reference`), not against the points as they were.

    A sighting that continues a track (seen in the previous image) beats one just re-acquired:
    only the latter is taken back. Otherwise both are, since a lost marker is far better than a
    wrong one; each tracker then re-acquires it on its own.
    """
    if not isinstance(gap_limit, RayGapLimit):
        gap_limit = RayGapLimit(float(gap_limit), k=None)
    max_gap = gap_limit.limit()
    confirm_acquired(trackers, cameras, max_gap)
    (uv0, st0, _), (uv1, st1, _) = trackers[0]._out[-1], trackers[1]._out[-1]
    both = (st0 != LOST) & (st1 != LOST)
    if not both.any():
        if last3d is not None and since is not None:
            since += 1  # no point is kept: every last point is a frame older
        return
    gap = np.full(len(both), np.nan)
    gap[both] = triangulate(cameras[1], uv1[both], cameras[0], uv0[both])[1]
    gap_limit.add(gap[both & (gap <= max_gap)])
    bad = np.flatnonzero(both & (gap > max_gap))
    if len(bad):
        fresh = [tr.reacquired[bad] for tr in trackers]
        only0, only1 = fresh[0] & ~fresh[1], fresh[1] & ~fresh[0]
        trackers[0].reject(bad[~only1])
        trackers[1].reject(bad[~only0])
    if last3d is not None:
        now = frame_points(trackers, cameras, -1)
        reference = last3d
        if reference_age is not None and since is not None:
            reference = moved_reference(trackers, cameras, last3d, since, now, reference_age)
        _reject_ambiguous(trackers, cameras, max_gap, reference)   # takes back only: the kept points stand
        (_, st0, _), (_, st1, _) = trackers[0]._out[-1], trackers[1]._out[-1]
        kept = (st0 != LOST) & (st1 != LOST)
        pts = np.where(kept[:, None], now, np.nan)
        if steps is not None and since is not None:
            jump = steps.check(pts, last3d, since)
            if jump.any():
                idx = np.flatnonzero(jump)
                log.info("3-D jump taken back: %s", ", ".join(
                    str(i) if names is None else str(names[i]) for i in idx))
                trackers[0].reject(idx)
                trackers[1].reject(idx)
                kept &= ~jump
        if since is not None:  # also without the jump check: the moved reference reads the ages
            since[kept] = 0
            since += 1
        last3d[kept] = pts[kept]


def _reject_ambiguous(trackers: list[MarkerTracker], cameras, max_gap: float, last3d: np.ndarray,
                      margin: float = 3.0) -> None:
    """Take back sightings that another, lost, marker explains better (an identity mix-up).

    The ray-gap test sees nothing along an epipolar line, nor a dot both views give the wrong
    marker. Let marker k be lost in view A, and j seen in both views. If k is seen in view B and
    the dot A gives j also meets k's ray from B (within ``max_gap``), A's dot may be k's own (the
    left bow peak on the right one's dot, both at one height in the mirror view); if k is lost in
    both views, both may have given j k's dot (the lip corner's neighbour on the corner's dot).
    Depth and place tell them apart: the dot, read as k's (paired with B's k, or as it is),
    lands at some distance from k's last accepted 3-D point, and, read as j's, at another from
    j's (``last3d (P, 3)``, lab mm; NaN where never accepted; or the points moved to this image,
    :func:`lipgen.recon.movedref.moved_reference`). Unless j's reading is ``margin`` times closer,
    j's sighting is taken back (in A; in both views when k is lost in both).
    """
    known = np.isfinite(last3d[:, 0])
    for a in range(2):
        (uv_a, st_a, _), (uv_b, st_b, _) = trackers[a]._out[-1], trackers[1 - a]._out[-1]
        js = np.flatnonzero((st_a != LOST) & (st_b != LOST) & known)
        ks = np.flatnonzero((st_a == LOST) & known & ((st_b != LOST) | (a == 0)))
        if len(ks) == 0 or len(js) == 0:
            continue
        jj, kk = np.repeat(js, len(ks)), np.tile(ks, len(js))
        cam_a, cam_b = cameras[a], cameras[1 - a]
        x_own = triangulate(cam_b, uv_b[jj], cam_a, uv_a[jj])[0]
        x_alt, g = x_own.copy(), np.zeros(len(jj))
        seen_b = st_b[kk] != LOST
        if seen_b.any():
            x_alt[seen_b], g[seen_b] = triangulate(cam_b, uv_b[kk[seen_b]], cam_a, uv_a[jj[seen_b]])
        mixed = ((g <= max_gap) & (jj != kk) & (np.linalg.norm(x_alt - last3d[kk], axis=1)
                                                < margin * np.linalg.norm(x_own - last3d[jj], axis=1)))
        trackers[a].reject(np.unique(jj[mixed]))
        trackers[1 - a].reject(np.unique(jj[mixed & ~seen_b]))


