"""A last pass over the tracks: sighting pairs whose 3-D point is out of place in the layout, every frame.

Two views that agree on a wrong dot give rays that meet: a marker on a neighbour's dot in both
views, or a dot moved along the epipolar line (its point deeper or shallower along the other
view's ray). The checks during tracking judge the 3-D layout at a run's first frame
(:class:`lipgen.recon.motioncheck.MotionCheck`) or act only where they can name a new dot
(:class:`lipgen.recon.recheck.IdentityCheck`), so a run that moves onto a wrong dot without a
jump its neighbours would not make, or a wrong run whose first frame fit, stays accepted.

:func:`take_back_out_of_place` judges every frame's pairs once the tracks are done: each pair's
3-D point is predicted from the other pairs of the same frame (leave one out, with the physics
prior when given; the out-of-place left out of the prediction,
:func:`lipgen.recon.firstframe.predict_layout`), and a pair farther from its prediction than
``k`` robust standard deviations of the frame's residuals (and than ``floor`` mm) is taken back
in both views: which view is wrong is not known, and a lost sighting costs far less than a
wrong one. The frame's own residuals set the limit, so a frame the layout fits poorly (a wide
mouth opening) keeps a wide one.
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen._validate import as_float_array
from lipgen.recon.firstframe import _residuals
from lipgen.recon.pointreg import layout_spacing
from lipgen.recon.track import LOST
from lipgen.recon.tracks import Tracks
from lipgen.rig.pinhole import PinholeCamera, triangulate

__all__ = ["out_of_place", "take_back", "take_back_out_of_place"]

log = logging.getLogger(__name__)


def out_of_place(
    tracks: tuple[Tracks, Tracks],
    cameras: tuple[PinholeCamera, PinholeCamera],
    rest_points,
    covariance=None,
    k: float = 3.0,
    floor: float = 3.0,
    min_pairs: int = 8,
) -> np.ndarray:
    """The sighting pairs whose 3-D point is out of place among the frame's other pairs.

    Parameters
    ----------
    tracks : (virtual, real) Tracks
    cameras : (virtual, real) PinholeCamera
    rest_points : (P, 3) float
        The markers at rest in the frame of ``cameras``, mm (NaN rows: no layout, not judged).
    covariance : (3P, 3P) float, optional
        The layout's physics prior (:func:`lipgen.recon.layoutprior.physics_layout_covariance`);
        None: the neighbours' Gaussian-weighted offsets.
    k : float
        Limit in robust standard deviations (1.4826 x median) of the frame's inlier residuals.
    floor : float
        The limit is never under this, mm.
    min_pairs : int
        Frames with fewer pairs seen in both views are not judged (at least 6).

    Returns
    -------
    (F, P) bool
        Pairs out of place. A marker far from every other (over 2.5 layout spacings: the nose)
        is never judged.
    """
    rest = as_float_array(rest_points, "rest_points", (None, 3), finite=False)
    tv, tr = tracks
    if tv.uv.shape != tr.uv.shape or tv.uv.shape[1] != len(rest):
        raise ValueError(
            f"tracks must both have shape (F, {len(rest)}, 2) like rest_points (P, 3), "
            f"got {tv.uv.shape} and {tr.uv.shape}"
        )
    if not (np.isfinite(k) and k > 0 and np.isfinite(floor) and floor >= 0):
        raise ValueError(f"k must be > 0 and floor >= 0 (mm), got k={k!r}, floor={floor!r}")
    if int(min_pairs) != min_pairs or min_pairs < 6:
        raise ValueError(f"min_pairs must be an integer >= 6, got {min_pairs!r}")
    has = np.all(np.isfinite(rest), axis=1)
    width = layout_spacing(rest[has])
    near = np.linalg.norm(rest[:, None] - rest[None], axis=2)
    np.fill_diagonal(near, np.inf)
    near[:, ~has] = np.inf
    judged = has & (near.min(1) <= 2.5 * width)
    both = tv.visible & tr.visible & has
    out = np.zeros(both.shape, dtype=bool)
    for t in np.flatnonzero(both.sum(1) >= min_pairs):
        X = np.full((len(rest), 3), np.nan)
        X[both[t]] = triangulate(cameras[1], tr.uv[t, both[t]], cameras[0], tv.uv[t, both[t]])[0]
        _, r, limit = _residuals(rest, X, both[t], width, k, floor, covariance=covariance)
        out[t] = both[t] & judged & (r > limit)
    return out


def take_back_out_of_place(
    tracks: tuple[Tracks, Tracks],
    cameras: tuple[PinholeCamera, PinholeCamera],
    rest_points,
    covariance=None,
    k: float = 3.0,
    floor: float = 3.0,
    min_pairs: int = 8,
    names=None,
) -> tuple[tuple[Tracks, Tracks], np.ndarray]:
    """The tracks with the out-of-place pairs (:func:`out_of_place`) taken back in both views.

    Parameters are those of :func:`out_of_place`; ``names`` (marker names) are for the log.

    Returns
    -------
    tracks : (virtual, real) Tracks
        New tracks: the pairs taken back are NaN and ``LOST``, and marked in ``rejected``.
    taken : (F, P) bool
        The pairs taken back.
    """
    taken = out_of_place(tracks, cameras, rest_points, covariance, k, floor, min_pairs)
    if taken.any():
        per = taken.sum(0)
        log.info(
            "%d sighting pair(s) out of place in the 3-D layout taken back (%s)",
            int(taken.sum()),
            ", ".join(f"{i if names is None else names[i]} {int(per[i])}" for i in np.flatnonzero(per)),
        )
    return take_back(tracks, taken), taken


def take_back(tracks: tuple[Tracks, Tracks], taken) -> tuple[Tracks, Tracks]:
    """The tracks with the sightings ``taken (F, P)`` taken back in both views: NaN, ``LOST`` and
    marked in ``rejected`` (new tracks; the same objects when nothing is taken)."""
    taken = np.asarray(taken, dtype=bool)
    if not taken.any():
        return tracks
    new = []
    for t in tracks:
        uv, status = t.uv.copy(), t.status.copy()
        uv[taken], status[taken] = np.nan, LOST
        rejected = (np.zeros(taken.shape, dtype=bool) if t.rejected is None else t.rejected.copy()) | taken
        new.append(Tracks(uv, status != LOST, status, t.score.copy(), rejected))
    return new[0], new[1]
