"""A last pass over the tracks: a marker's run that sits where the layout puts a lost neighbour.

Most accepted sightings far from the truth are wrong from the marker's first accepted frame
(``renders/examples/tracking/over3px_sources.md``): a corner marker on the dot of its neighbour,
whose own marker stays lost (an identity shift), or on the mouth corner's crease (a lure). The
per-frame layout check (:func:`lipgen.recon.outofplace.out_of_place`) sets its limit from the
frame's residuals, which widen when the mouth is open; it asks "is the point far from its own
place", not "is it at someone else's".

:func:`lost_neighbour_runs` asks the second question over a marker's whole run of frames seen in
both views: in every frame where a close neighbour is not seen in both views, the marker's 3-D
point is compared with the layout's prediction (from the other pairs, the marker left out) of
its own position (``d_own``) and of the lost neighbour's (``d_nb``). A run whose median ``d_nb``
is under ``ratio`` times its median ``d_own`` is on the neighbour's place and is taken back in
both views; with ``neither``, so is a run farther than ``neither`` layout spacings from its own
place and from every lost neighbour's. Truth-free: only the tracks, cameras and rest layout.
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen._validate import as_float_array
from lipgen.recon.firstframe import predict_layout
from lipgen.recon.outofplace import take_back
from lipgen.recon.pointreg import layout_spacing
from lipgen.recon.tracks import Tracks
from lipgen.rig.pinhole import PinholeCamera, triangulate

__all__ = ["runs", "close_neighbours", "run_distances", "lost_neighbour_runs", "take_back_lost_neighbour"]

log = logging.getLogger(__name__)


def runs(seen) -> list[tuple[int, int]]:
    """The runs of True in ``seen (F,)`` as (first, end) frame pairs (end exclusive)."""
    s = np.concatenate([[False], np.asarray(seen, dtype=bool), [False]]).astype(np.int8)
    d = np.diff(s)
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))


def close_neighbours(rest, reach: float = 1.5) -> tuple[np.ndarray, np.ndarray, float]:
    """Which markers are close neighbours in the rest layout, and which are judged.

    Parameters
    ----------
    rest : (P, 3) float
        The layout at rest, mm (NaN rows: no layout).
    reach : float
        Neighbours lie within this many layout spacings.

    Returns
    -------
    near : (P, P) bool
        ``near[i, j]``: j is a close neighbour of i (never i itself; both judged).
    judged : (P,) bool
        Markers with a layout within 2.5 spacings of another (not the nose).
    width : float
        The layout spacing, mm.
    """
    has = np.all(np.isfinite(rest), axis=1)
    width = layout_spacing(rest[has])
    d = np.linalg.norm(rest[:, None] - rest[None], axis=2)
    d[~has] = np.inf
    d[:, ~has] = np.inf
    np.fill_diagonal(d, np.inf)
    judged = has & (d.min(1) <= 2.5 * width)
    near = (d <= reach * width) & judged[:, None] & judged[None, :]
    return near, judged, width


def run_distances(rest, X, both, i: int, frames, near_i, width: float, covariance=None,
                  min_pairs: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """A marker's distances from its own predicted place and from its lost neighbours', per frame.

    Parameters
    ----------
    rest : (P, 3) float
        The layout at rest, mm.
    X : (F, P, 3) float
        The pairs' 3-D points, mm (read where ``both``).
    both : (F, P) bool
        Seen in both views.
    i : int
        The marker.
    frames : sequence of int
        The frames of its run.
    near_i : (P,) bool
        Its close neighbours.
    width : float
        The layout spacing, mm (the fallback prediction's width without ``covariance``).
    covariance : (3P, 3P) float, optional
        The physics prior (:func:`lipgen.recon.layoutprior.physics_layout_covariance`).
    min_pairs : int
        Frames with fewer other pairs are not judged.

    Returns
    -------
    d_own : (n,) float
        Per frame of ``frames``, the point's distance from its own prediction (NaN: not judged).
    d_nb : (n, P) float
        Its distance from each neighbour's prediction where that neighbour is not seen in both
        views (NaN elsewhere).
    """
    P = len(rest)
    d_own = np.full(len(frames), np.nan)
    d_nb = np.full((len(frames), P), np.nan)
    for n, t in enumerate(frames):
        lost = near_i & ~both[t]
        use = both[t].copy()
        use[i] = False
        if not lost.any() or use.sum() < min_pairs:
            continue
        pred = predict_layout(rest, np.where(use[:, None], X[t], 0.0), use, width, covariance)
        d_own[n] = np.linalg.norm(X[t, i] - pred[i])
        d_nb[n, lost] = np.linalg.norm(X[t, i] - pred[lost], axis=1)
    return d_own, d_nb


def _verdict(d_own, d_nb, ratio: float, neither: float | None, width: float) -> bool:
    """Whether a run goes: on a lost neighbour's place (or, with ``neither``, on nobody's).

    ``d_own (n,)`` and ``d_nb (n, P)`` from :func:`run_distances`; a neighbour counts where it is
    lost in at least min(3, frames judged) frames."""
    judged = np.isfinite(d_own)
    if not judged.any():
        return False
    need = min(3, int(judged.sum()))
    far = []
    for j in np.flatnonzero((np.isfinite(d_nb) & judged[:, None]).sum(0) >= need):
        f = judged & np.isfinite(d_nb[:, j])
        own, nb = float(np.median(d_own[f])), float(np.median(d_nb[f, j]))
        if nb < ratio * own:
            return True
        far.append(nb)
    if neither is None or not far:
        return False
    return bool(min(far) > neither * width and np.median(d_own[judged]) > neither * width)


def lost_neighbour_runs(
    tracks: tuple[Tracks, Tracks],
    cameras: tuple[PinholeCamera, PinholeCamera],
    rest_points,
    covariance=None,
    ratio: float = 0.5,
    neither: float | None = None,
    reach: float = 1.5,
    min_pairs: int = 8,
) -> np.ndarray:
    """The sighting pairs of runs that sit on a lost neighbour's place in the layout.

    Parameters
    ----------
    tracks : (virtual, real) Tracks
    cameras : (virtual, real) PinholeCamera
    rest_points : (P, 3) float
        The markers at rest in the frame of ``cameras``, mm (NaN rows: not judged).
    covariance : (3P, 3P) float, optional
        The physics prior; None: the neighbours' Gaussian-weighted offsets.
    ratio : float
        A run goes when its median distance from a lost neighbour's predicted place is under this
        times its median distance from its own (in (0, 1]).
    neither : float or None
        With a number: a run also goes when its medians from its own place and from every lost
        neighbour's are over this many layout spacings. None: not.
    reach : float
        Close neighbours lie within this many layout spacings at rest.
    min_pairs : int
        Frames with fewer other pairs seen in both views are not judged (at least 6).

    Returns
    -------
    (F, P) bool
        The pairs taken back (whole runs).
    """
    rest = as_float_array(rest_points, "rest_points", (None, 3), finite=False)
    tv, tr = tracks
    if tv.uv.shape != tr.uv.shape or tv.uv.shape[1] != len(rest):
        raise ValueError(f"tracks must both have shape (F, {len(rest)}, 2) like rest_points (P, 3), "
                         f"got {tv.uv.shape} and {tr.uv.shape}")
    if not (np.isfinite(ratio) and 0 < ratio <= 1):
        raise ValueError(f"ratio must be in (0, 1] (a share of the distance from its own place), "
                         f"got {ratio!r}")
    if neither is not None and not (np.isfinite(neither) and neither > 0):
        raise ValueError(f"neither must be None or a number of layout spacings > 0, got {neither!r}")
    if int(min_pairs) != min_pairs or min_pairs < 6:
        raise ValueError(f"min_pairs must be an integer >= 6, got {min_pairs!r}")
    near, judged, width = close_neighbours(rest, reach)
    both = tv.visible & tr.visible & np.all(np.isfinite(rest), axis=1)
    X = np.full(tv.uv.shape[:2] + (3,), np.nan)
    if both.any():
        X[both] = triangulate(cameras[1], tr.uv[both], cameras[0], tv.uv[both])[0]
    out = np.zeros(both.shape, dtype=bool)
    for i in np.flatnonzero(judged & near.any(1)):
        for a, b in runs(both[:, i]):
            frames = range(a, b)
            d_own, d_nb = run_distances(rest, X, both, i, frames, near[i], width, covariance, min_pairs)
            if _verdict(d_own, d_nb, ratio, neither, width):
                out[a:b, i] = True
    return out


def take_back_lost_neighbour(
    tracks, cameras, rest_points, covariance=None, ratio: float = 0.5, neither: float | None = None, names=None
) -> tuple[tuple[Tracks, Tracks], np.ndarray]:
    """The tracks with the runs of :func:`lost_neighbour_runs` taken back in both views.

    Returns the new (virtual, real) tracks and the (F, P) bool pairs taken back; ``names`` are for the log."""
    taken = lost_neighbour_runs(tracks, cameras, rest_points, covariance, ratio, neither)
    if taken.any():
        per = taken.sum(0)
        log.info("%d sighting pair(s) on a lost neighbour's place taken back (%s)", int(taken.sum()),
                 ", ".join(f"{i if names is None else names[i]} {int(per[i])}" for i in np.flatnonzero(per)))
    return take_back(tracks, taken), taken
