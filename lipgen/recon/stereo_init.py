"""The first frame's lures, dropped in 3-D before its dots are matched to the marker layout.

Matching each view's dots to the expected 2-D layout on its own (:func:`lipgen.recon.pointreg.
match_to_expected`) fails where a view shows dark blobs that are no ink (the gaps between the
teeth, the nostrils, the nose's shadow) and few of the real dots (a defocused mirror view): on
hard-preset first frames, whole rows of markers were matched one dot along, and the ray-gap test
sees few of these, as the lips' rows run along the epipolar lines. In 3-D most lures stand out:
a shadow's two sightings do not meet, and a tooth gap lies behind the lips. So only the dots
that pair with a dot of the other view (rays within ``max_gap``) at a point near the marker
layout, moved to where the dots are, are matched (:func:`layout_dots`). The layout is moved by a
translation only: its residuals to the subject's own dots are 1-3 mm (its own lip shape, the
head's turn), so ``near`` is generous; it removes lures, it does not match.

Off by default (``ReconstructSettings.first_frame_lures``). Tracking hard validation seeds 7-10
(40 frames, with ``DotSettings.window=1.25``; mirror / direct px RMS, accepted share, sightings
over 3 px per view), without -> with it: seed 7 0.74 / 0.82 px, 57 %, 3 / 3 -> 1.23 / 0.54 px,
48 %, 3 / 0; seed 8 2.22 / 1.77 px, 32 %, 12 / 9 -> 1.62 / 1.65 px, 56 %, 13 / 12; seed 9
0.81 / 0.79 px, 61 %, 5 / 5 -> 0.43 / 0.44 px, 59 %, 0 / 0; seed 10 0.47 / 0.39 px, 69 %,
0 / 0 -> 1.67 / 1.76 px, 55 %, 7 / 7. Mixed, hence off.
A match whose dot is dropped is left to the tracker, which acquires
the marker later from the layout (a dot taken out before matching would instead leave its
marker to a neighbour's dot: on ``easy`` that made ten wrong matches).
"""

from __future__ import annotations

import numpy as np

from lipgen._validate import as_float_array
from lipgen.rig.pinhole import PinholeCamera, triangulate

__all__ = ["stereo_candidates", "layout_dots", "repose_layout"]


def stereo_candidates(dots_v: np.ndarray, dots_r: np.ndarray, cameras: tuple[PinholeCamera, PinholeCamera],
                      max_gap: float) -> tuple[np.ndarray, np.ndarray]:
    """3-D points of every pair of dots (virtual, real) whose rays pass within ``max_gap`` mm.

    Parameters
    ----------
    dots_v, dots_r : (m, 2), (n, 2) float
        Dots in the virtual and the real view, pixels.
    cameras : (virtual, real) PinholeCamera
    max_gap : float
        Largest distance between the two rays, mm.

    Returns
    -------
    points : (c, 3) float
        Ray midpoints of the pairs kept.
    pairs : (c, 2) int
        Their dot indices (virtual, real).
    """
    dv = as_float_array(dots_v, "dots_v", (None, 2))
    dr = as_float_array(dots_r, "dots_r", (None, 2))
    if len(dv) == 0 or len(dr) == 0:
        return np.zeros((0, 3)), np.zeros((0, 2), dtype=np.int64)
    iv, ir = np.meshgrid(np.arange(len(dv)), np.arange(len(dr)), indexing="ij")
    iv, ir = iv.ravel(), ir.ravel()
    X, gap = triangulate(cameras[1], dr[ir], cameras[0], dv[iv])
    ok = gap <= max_gap
    return X[ok], np.column_stack([iv[ok], ir[ok]])


def _similarity_3d(src: np.ndarray, dst: np.ndarray, max_scale_change: float = 0.15) -> np.ndarray:
    """(4, 4) least-squares similarity with dst ~ s R src + t (Umeyama), the scale kept near 1."""
    ms, md = src.mean(0), dst.mean(0)
    a, b = src - ms, dst - md
    U, S, Vt = np.linalg.svd(b.T @ a)
    d = np.ones(3)
    d[2] = np.sign(np.linalg.det(U @ Vt)) or 1.0
    R = U @ np.diag(d) @ Vt
    var = (a * a).sum()
    s = float(np.clip((S * d).sum() / var, 1 - max_scale_change, 1 + max_scale_change)) if var > 0 else 1.0
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = s * R, md - s * R @ ms
    return T


def _best_translation(points: np.ndarray, model: np.ndarray, tol: float, reach: float) -> np.ndarray:
    """The offset (candidate minus marker, at most ``reach`` mm) that puts most markers within ``tol``."""
    offsets = (points[:, None] - model[None]).reshape(-1, 3)
    offsets = offsets[np.linalg.norm(offsets, axis=1) <= reach]
    if len(offsets) == 0:
        return np.zeros(3)
    best, best_count, best_cost = np.zeros(3), -1, np.inf
    for chunk in np.array_split(offsets, max(1, len(offsets) // 256)):
        moved = model[None] + chunk[:, None]                                         # (h, P, 3)
        d = np.linalg.norm(moved[:, :, None] - points[None, None], axis=3).min(2)    # (h, P)
        count = (d <= tol).sum(1)
        cost = np.where(d <= tol, d, tol).sum(1)
        for h in np.flatnonzero(count == count.max()):
            if count[h] > best_count or (count[h] == best_count and cost[h] < best_cost):
                best, best_count, best_cost = chunk[h], int(count[h]), float(cost[h])
    return best


def layout_dots(dots_v, dots_r, cameras: tuple[PinholeCamera, PinholeCamera], model_points,
                max_gap: float = 1.0, near: float = 4.0, reach: float = 20.0
                ) -> tuple[np.ndarray, np.ndarray]:
    """Which dots of each view have a partner in the other view that puts them near the layout.

    A dot is kept when its ray meets (within ``max_gap`` mm) the ray of a dot in the other view
    at a point within ``near`` mm of a marker of the layout ``model_points (P, 3)`` moved by the
    translation (up to ``reach`` mm) that brings the most markers within ``near`` of such points,
then by the similarity that fits them to their nearest points (twice).
    The nose's shadow, a nostril seen in one view only, or a gap between the teeth (behind the
    lips) are dropped. Returns (keep_v (m,) bool, keep_r (n,) bool); all True when fewer than 4
    markers could be placed (nothing is known then).
    """
    M = as_float_array(model_points, "model_points", (None, 3), finite=False)
    M = M[np.all(np.isfinite(M), axis=1)]
    keep_v, keep_r = np.ones(len(dots_v), dtype=bool), np.ones(len(dots_r), dtype=bool)
    placed = _placed(dots_v, dots_r, cameras, M, max_gap, near, reach, least=4)
    if placed is None:
        return keep_v, keep_r
    moved, X, pairs = placed
    close = np.linalg.norm(X[:, None] - moved[None], axis=2).min(1) <= near
    keep_v[:], keep_r[:] = False, False
    keep_v[pairs[close, 0]] = True
    keep_r[pairs[close, 1]] = True
    return keep_v, keep_r


def _place(X: np.ndarray, M: np.ndarray, near: float, reach: float) -> np.ndarray:
    """The layout ``M (P, 3)`` moved to the candidates ``X (c, 3)``: the translation (up to ``reach``)
    that brings the most markers within ``near`` of one, then the similarity of the markers to their
    nearest candidates, twice (the head turns)."""
    moved = M + _best_translation(X, M, near, reach)
    for _ in range(2):
        d = np.linalg.norm(moved[:, None] - X[None], axis=2)
        hit = d.min(1) <= near
        if hit.sum() < 4:
            break
        T = _similarity_3d(M[hit], X[d[hit].argmin(1)])
        moved = M @ T[:3, :3].T + T[:3, 3]
    return moved


def repose_layout(dots_v, dots_r, cameras: tuple[PinholeCamera, PinholeCamera], model_points,
                  max_gap: float = 1.0, near: float = 4.0, reach: float = 40.0, least: int = 6
                  ) -> np.ndarray | None:
    """The layout ``model_points (P, 3)`` moved to where the two views' dot pairs place it, or None.

    As :func:`layout_dots` places it (pairs of dots whose rays meet within ``max_gap`` mm, a
    translation of up to ``reach`` mm, then a similarity), for a first frame whose pose is far from
    the layout's (``hard`` 58: 30-50 px). None where fewer than ``least`` markers end within ``near``
    mm of a pair's point (nothing is known then). Rows of ``model_points`` that are not finite stay NaN.

    Parameters
    ----------
    dots_v, dots_r : (m, 2), (n, 2) float
        The virtual and the real view's dots, px.
    cameras : (virtual, real) PinholeCamera
    model_points : (P, 3) float
        The layout at rest in the cameras' frame, mm.
    max_gap, near, reach : float
        mm; ``max_gap`` is this placement's own ray-gap limit (as :func:`layout_dots`'s), not the
        tracker's ``max_ray_gap``.

    Returns
    -------
    (P, 3) float or None
        The moved layout, mm.
    """
    M0 = as_float_array(model_points, "model_points", (None, 3), finite=False)
    ok = np.all(np.isfinite(M0), axis=1)
    placed = _placed(dots_v, dots_r, cameras, M0[ok], max_gap, near, reach, least)
    if placed is None:
        return None
    out = np.full(M0.shape, np.nan)
    out[ok] = placed[0]
    return out


def _placed(dots_v, dots_r, cameras, M, max_gap, near, reach, least):
    """The finite layout ``M (P, 3)`` moved onto the views' dot pairs (:func:`_place`), with the pairs'
    points ``X (c, 3)`` and dot indices ``pairs (c, 2)``; None where fewer than 4 pairs or markers, or
    fewer than ``least`` markers end within ``near`` mm of a point."""
    X, pairs = stereo_candidates(dots_v, dots_r, cameras, max_gap)
    if len(X) < 4 or len(M) < 4:
        return None
    moved = _place(X, M, near, reach)
    if np.count_nonzero(np.linalg.norm(moved[:, None] - X[None], axis=2).min(1) <= near) < least:
        return None
    return moved, X, pairs
