"""Where each marker should be now: its last accepted 3-D point moved with its neighbours since then.

The identity check of :func:`lipgen.recon.viewcheck.check_views` judges a sighting by how far its
point lands from the marker's reference. The last accepted point is a good reference only while
it is recent: after a fast jaw burst a marker taken back for a few frames has a last point 8-18 mm
stale on ``hard`` 27 (``renders/examples/tracking/hard15m_seed27.md``), so its right sighting
lands far from it and is taken back again, frame after frame. Here the last point is carried to
the current frame by the motion of the markers seen in both views both then and now, as
:class:`lipgen.recon.motioncheck.MotionCheck` predicts a step: a 3-D similarity of those markers,
plus the Gaussian-weighted mean of their residual offsets (neighbours on the same lip move
alike; a jaw opening is not a similarity). The marker's own sighting now is never used.
"""

from __future__ import annotations

import numpy as np

from lipgen.recon.motioncheck import frame_points
from lipgen.recon.pointreg import layout_spacing
from lipgen.recon.stereo_init import _similarity_3d
from lipgen.recon.track import MarkerTracker

__all__ = ["moved_reference"]


def _weights(points: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(n,) Gaussian weights of ``points (n, 3)`` by their distance to ``x (3,)``, the width the
    median distance between neighbouring points (a marker spacing); one point: weight 1."""
    if len(points) < 2:
        return np.ones(len(points))
    width = layout_spacing(points)
    return np.exp(-0.5 * (np.linalg.norm(points - x, axis=1) / width) ** 2) + 1e-12


def _robust_similarity(
    before: np.ndarray, now: np.ndarray, o: np.ndarray, floor: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """The similarity from ``before[o]`` to ``now[o]`` without the markers that do not follow it.

    A wrong sighting now among the markers would drag every reference near it. One marker at a
    time, while 4 are left (a similarity from 3 can turn wild): the one whose removal fits the
    others best is dropped if, under the fit without it, it lies more than ``floor`` mm and 3
    times the others' median off.
    Returns (4, 4) and the markers kept.
    """
    while len(o) >= 5:
        best = None
        for i in range(len(o)):
            rest = np.delete(o, i)
            T = _similarity_3d(before[rest], now[rest])
            r = np.linalg.norm(now[o] - (before[o] @ T[:3, :3].T + T[:3, 3]), axis=1)
            cost = float(np.sum(np.delete(r, i) ** 2))
            if best is None or cost < best[0]:
                best = (cost, i, r)
        _, i, r = best
        if r[i] <= max(floor, 3.0 * float(np.median(np.delete(r, i)))):
            break
        o = np.delete(o, i)
    return _similarity_3d(before[o], now[o]), o


def moved_reference(
    trackers: list[MarkerTracker],
    cameras,
    last3d: np.ndarray,
    since: np.ndarray,
    now: np.ndarray,
    min_age: int = 1,
    min_common: int = 4,
) -> np.ndarray:
    """Each marker's last accepted point carried to the current image by its neighbours' motion.

    Parameters
    ----------
    trackers : (virtual, real) MarkerTracker
        Their stored images (``_out``) give the other markers' points at each marker's last frame.
    cameras : (virtual, real) PinholeCamera
    last3d : (P, 3) float
        Each marker's last accepted point, lab mm; NaN where never accepted.
    since : (P,) float
        Images since ``last3d`` (1: accepted in the image before the current one).
    now : (P, 3) float
        The points seen in both views in the current image, lab mm; NaN elsewhere.
    min_age : int
        Only points at least this many images old are moved (1: all; 2: a point from the image
        before is kept as it is).
    min_common : int
        Fewest other markers seen both then and now for the similarity (>= 4); with fewer (but
        one at least), their Gaussian-weighted mean step; with none, the last point is kept.

    Returns
    -------
    (P, 3) float
        The reference per marker, lab mm: ``last3d`` where not moved.
    """
    last3d = np.asarray(last3d, dtype=float)
    P = len(last3d)
    now = np.asarray(now, dtype=float)
    since = np.asarray(since, dtype=float)
    if now.shape != (P, 3) or since.shape != (P,):
        raise ValueError(
            f"now must be ({P}, 3) and since ({P},) like last3d, got {now.shape} and {since.shape}"
        )
    if int(min_age) != min_age or min_age < 1 or int(min_common) != min_common or min_common < 4:
        raise ValueError(
            f"min_age must be an integer >= 1 and min_common >= 4, got {min_age!r}, {min_common!r}"
        )
    out = last3d.copy()
    t = len(trackers[0]._out) - 1
    seen_now = np.isfinite(now[:, 0])
    age = np.where(np.isfinite(since), since, 0).astype(int)
    frames: dict[int, np.ndarray] = {}
    fits: dict[tuple[int, bytes], tuple[np.ndarray, np.ndarray]] = {}  # lost markers share a fit
    for m in np.flatnonzero(np.isfinite(last3d[:, 0]) & (age >= min_age) & (age <= t)):
        s = t - int(age[m])
        if s not in frames:
            frames[s] = frame_points(trackers, cameras, s)
        before = frames[s]
        o = np.flatnonzero(np.isfinite(before[:, 0]) & seen_now)
        o = o[o != m]
        if len(o) == 0:
            continue
        if len(o) < min_common:  # too few for a similarity: their mean step, nearer ones first
            w = _weights(before[o], last3d[m])
            out[m] = last3d[m] + (w @ (now[o] - before[o])) / float(w.sum())
            continue
        key = (s, o.tobytes())
        if key not in fits:
            fits[key] = _robust_similarity(before, now, o)
        T, o = fits[key]
        moved = before[o] @ T[:3, :3].T + T[:3, 3]
        w = _weights(before[o], last3d[m])
        # Far from every neighbour (the nose) the offsets shrink towards the similarity alone.
        off = (w @ (now[o] - moved)) / max(float(w.sum()), 1.0)
        out[m] = T[:3, :3] @ last3d[m] + T[:3, 3] + off
    return out
