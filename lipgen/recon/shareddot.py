"""Two markers on one dot in both views: the layout says whose it is, the other is taken back.

A dot is one marker's. When the tracks hold two markers on the same dot in both views, their rays
meet and every check that judges one marker at a time passes: each pair's point is a real dot's,
on the lip, near the layout. On the 20 spent ``hard`` development sets (83-122, truth read for
the diagnosis only) 70 pair-frames held two markers within 0.7 px of each other in both views, and
in every one of them one marker was wrong (``lower_corner_right`` on ``corner_right``'s dot for 34
frames of ``hard`` 119, from the first frame; ``corner_right`` on ``lower_corner_right``'s for 20 of
``hard`` 111). No two markers' true projections came within 2.5 px of each other in both views; the
nearest two distinct sightings seen in both views were 3.7 px apart.

:func:`shared_dots` finds them (both sightings within ``tol`` pixels in each view) and judges each
span of consecutive shared frames of a pair of markers as :func:`lipgen.recon.crosscheck.arbitrate`
judges a dispute: the shared point is compared with each marker's position predicted from the
frame's other pairs (:func:`lipgen.recon.firstframe.predict_layout`, the physics prior with
``covariance``). The marker whose prediction lies nearer, on average over the span, by ``ratio``
keeps the dot; the other is taken back in both views. Where neither is nearer by that much, both
are: a wrong sighting costs far more than a lost one.
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen.recon.outofplace import take_back
from lipgen.recon.track import LOST
from lipgen.recon.tracks import Tracks

__all__ = ["shared_dots", "take_back_shared", "shared_dot_line"]

log = logging.getLogger(__name__)


def _seen(t: Tracks) -> np.ndarray:
    return (t.status != LOST) & np.all(np.isfinite(t.uv), axis=-1)


def _spans(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of each run of True in a 1-D mask."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def shared_dots(tracks: tuple[Tracks, Tracks], cameras, rest_points, tol: float, covariance=None,
                ratio: float = 0.6, min_pairs: int = 6) -> tuple[np.ndarray, list[dict]]:
    """The sightings to take back where two markers hold one dot in both views (see the module docstring).

    Parameters
    ----------
    tracks : (virtual, real) Tracks
        F frames, P markers each.
    cameras : (virtual, real) PinholeCamera
    rest_points : (P, 3) float
        The markers at rest in the frame of ``cameras``, mm (NaN rows: no layout; such a marker
        is never judged the owner).
    tol : float
        Two sightings nearer than this in a view (pixels) are on one dot; at most half the
        detector's one-dot distance, so that two dots fitted apart are never taken for one.
    covariance : (3P, 3P) float, optional
        The layout's physics prior (:func:`lipgen.recon.layoutprior.physics_layout_covariance`).
    ratio : float
        The owner's mean distance to its prediction must be under ``ratio`` times the other's.
    min_pairs : int
        Frames with fewer other pairs seen in both views give no prediction.

    Returns
    -------
    taken : (F, P) bool
        Sightings to take back (both views).
    spans : list of dict
        One per span: ``markers`` (i, j), ``frames`` (start, stop), ``owner`` (i, j or -1: neither),
        ``distance`` (mean distance of the shared point to each marker's prediction, mm; None where
        no frame of the span gave a prediction).
    """
    from lipgen.recon.firstframe import predict_layout
    from lipgen.recon.pointreg import layout_spacing
    from lipgen.rig.pinhole import triangulate

    tv, tr = tracks
    rest = np.asarray(rest_points, dtype=float)
    F, P = tv.uv.shape[:2]
    if tr.uv.shape != tv.uv.shape or rest.shape != (P, 3):
        raise ValueError(f"tracks must both have shape (F, {len(rest)}, 2) like rest_points (P, 3), "
                         f"got {tv.uv.shape}, {tr.uv.shape} and rest_points {rest.shape}")
    if not (np.isfinite(tol) and tol > 0) or not (np.isfinite(ratio) and 0 < ratio <= 1):
        raise ValueError(f"tol must be > 0 (pixels) and ratio in (0, 1], got tol={tol!r}, ratio={ratio!r}")
    both = _seen(tv) & _seen(tr)
    near = np.ones((F, P, P), dtype=bool)
    for t in (tv, tr):
        uv = np.where(both[..., None], t.uv, np.nan)
        near &= np.linalg.norm(uv[:, :, None] - uv[:, None], axis=-1) < tol   # NaN compares False
    near &= ~np.eye(P, dtype=bool)
    taken = np.zeros((F, P), dtype=bool)
    spans: list[dict] = []
    if not near.any():
        return taken, spans
    has = np.all(np.isfinite(rest), axis=1)
    width = layout_spacing(rest[has])
    X = np.full((F, P, 3), np.nan)
    X[both] = triangulate(cameras[1], tr.uv[both], cameras[0], tv.uv[both])[0]
    for i, j in zip(*np.nonzero(np.triu(near.any(axis=0), 1)), strict=True):
        for start, stop in _spans(near[:, i, j]):
            d = np.full((stop - start, 2), np.nan)
            for k, f in enumerate(range(start, stop)):
                use = both[f] & has
                use[[i, j]] = False
                if use.sum() >= min_pairs:
                    pred = predict_layout(rest, X[f], use, width, covariance)
                    shared = 0.5 * (X[f, i] + X[f, j])
                    d[k] = np.linalg.norm(shared - pred[[i, j]], axis=1)
            ok = np.all(np.isfinite(d), axis=1)
            di, dj = d[ok].mean(axis=0) if ok.any() else (np.nan, np.nan)
            owner = i if di < ratio * dj else j if dj < ratio * di else -1
            for m in (i, j):
                if m != owner:
                    taken[start:stop, m] = True
            spans.append({"markers": (int(i), int(j)), "frames": (start, stop), "owner": int(owner),
                          "distance": None if np.isnan(di) else (float(di), float(dj))})
    return taken, spans


def take_back_shared(tracks: tuple[Tracks, Tracks], cameras, rest_points, tol: float, covariance=None,
                     names=None, **kwargs) -> tuple[tuple[Tracks, Tracks], list[dict]]:
    """The tracks with :func:`shared_dots`' sightings taken back in both views (NaN, ``LOST``, marked
    ``rejected``), and its spans; ``names`` (marker names) are for the log."""
    taken, spans = shared_dots(tracks, cameras, rest_points, tol, covariance, **kwargs)

    def name(m):
        return str(m) if names is None else names[m]

    for s in spans:
        (i, j), (start, stop), owner = s["markers"], s["frames"], s["owner"]
        log.info("%s and %s on one dot in both views, frames %d-%d: %s", name(i), name(j), start, stop - 1,
                 "neither kept" if owner < 0 else f"{name(owner)} keeps it, {name(j if owner == i else i)} "
                 "taken back")
    return take_back(tracks, taken), spans


def shared_dot_line(spans: list[dict] | None, names) -> str | None:
    """One sentence on what :func:`take_back_shared` did, for ``lipgen reconstruct``'s output and the
    report; None where no two markers shared a dot (or the reconstruction predates the check).
    ``names``: the markers' names, indexed as in ``spans``."""
    if not spans:
        return None
    parts = []
    for s in spans[:4]:
        (i, j), (start, stop), owner = s["markers"], s["frames"], s["owner"]
        frames = f"frame {start}" if stop - start == 1 else f"frames {start}-{stop - 1}"
        if owner < 0:
            parts.append(f"{names[i]} and {names[j]} in {frames}, both taken back (the layout could not "
                         "tell whose)")
        else:
            parts.append(f"{names[j if owner == i else i]} on {names[owner]}'s in {frames}, taken back")
    more = f"; and {len(spans) - 4} more span(s)" if len(spans) > 4 else ""
    return "Two markers held one dot in both views: " + "; ".join(parts) + more + "."
