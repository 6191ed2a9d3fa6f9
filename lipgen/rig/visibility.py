"""Ray casting against triangle soups: which points a camera sees (occlusion by surfaces).

The dataset's visibility truth comes from here, not from the renderer, so it is exact geometry
and independent of the rasteriser. Each triangle's pixel bounding box culls the points whose line
of sight could cross it before the exact Moller-Trumbore test (few points, many triangles: the
points sorted by x, each box's run of them found by binary search, then tested in y). The boxes
are taken in the camera's pinhole image (without lens distortion), where they hold every point
whose line of sight crosses the triangle.
"""

from __future__ import annotations

import numpy as np

from lipgen.rig.pinhole import PinholeCamera

__all__ = ["segment_hits", "occluded"]


def segment_hits(origins: np.ndarray, targets: np.ndarray, triangles: np.ndarray,
                 end_gap: float = 0.01) -> np.ndarray:
    """(p,) bool: does segment ``origins[i] -> targets[i]`` cross triangle ``triangles[i]``?

    Parameters
    ----------
    origins, targets : (p, 3) float
        Segment ends, mm.
    triangles : (p, 3, 3) float
        One triangle per segment (pairs, not all-against-all).
    end_gap : float
        Crossings within this distance (mm) of either end do not count, so a point on a
        surface does not hide itself.
    """
    d = (targets - origins).T  # component rows: the same products and sums as np.cross / np.sum
    length = np.sqrt(_dot(d, d))
    A = triangles[:, 0].T
    e1, e2 = triangles[:, 1].T - A, triangles[:, 2].T - A
    p = _cross(d, e2)
    det = _dot(e1, p)
    ok = np.abs(det) > 1e-12 * np.maximum(length, 1.0) ** 3
    inv = np.divide(1.0, det, out=np.zeros_like(det), where=ok)
    s = origins.T - A
    u = _dot(s, p) * inv
    q = _cross(s, e1)
    v = _dot(d, q) * inv
    t = _dot(e2, q) * inv
    gap = end_gap / np.maximum(length, 1e-300)
    return ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > gap) & (t < 1 - gap)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot of (3, p) arrays, summed in np.sum's order."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products of (3, p) arrays (np.cross's products)."""
    return np.stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


_PAIR_BLOCK = 1 << 22  # candidate pairs per block: bounds the memory of the search


def _box_pairs(q: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every ``(i, j)`` with ``lo[:, j] <= q[i] <= hi[:, j]`` (both coordinates), as two index arrays.

    The points are sorted by x, so the points inside box ``j``'s x-range are one run of that order
    (two binary searches per box); only those are tested in y. The same pairs as testing every
    point against every box, at a cost in the boxes and the pairs found rather than their product.

    Parameters
    ----------
    q : (p, 2) float
        Points (finite).
    lo, hi : (2, m) float
        Box corners (may be infinite).
    """
    order = np.argsort(q[:, 0], kind="stable")
    xs = q[order, 0]
    start = np.searchsorted(xs, lo[0], side="left")  # the first point with x >= lo
    counts = np.searchsorted(xs, hi[0], side="right") - start  # ... and x <= hi
    pair_q, pair_t = [], []
    ends = np.cumsum(counts)
    b0 = 0
    while b0 < len(counts):  # blocks of boxes holding at most _PAIR_BLOCK candidates (at least one box)
        b1 = max(int(np.searchsorted(ends, (ends[b0 - 1] if b0 else 0) + _PAIR_BLOCK, side="right")), b0 + 1)
        c = counts[b0:b1]
        box = np.repeat(np.arange(b0, b1), c)
        first = np.repeat(start[b0:b1] - (np.cumsum(c) - c), c)  # run start, less the run's offset
        i = order[first + np.arange(len(box))]
        y = q[i, 1]
        ok = (y >= lo[1][box]) & (y <= hi[1][box])
        pair_q.append(i[ok])
        pair_t.append(box[ok])
        b0 = b1
    if not pair_q:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(pair_q), np.concatenate(pair_t)


def _pinhole(camera: PinholeCamera, X: np.ndarray) -> np.ndarray:
    """(p, 2) pixels of world points ``X`` (p, 3) through ``camera`` without its lens distortion
    (NaN at or behind the camera)."""
    R, t = camera.R, camera.t
    Xc = [X[:, 0] * R[i, 0] + X[:, 1] * R[i, 1] + X[:, 2] * R[i, 2] + t[i] for i in range(3)]
    z = Xc[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(z > 0, 1.0 / z, np.nan)
    K = camera.K
    return np.stack([Xc[0] * inv * K[0, 0] + K[0, 2], Xc[1] * inv * K[1, 1] + K[1, 2]], axis=1)


def occluded(camera: PinholeCamera, points, triangles, end_gap: float = 0.01) -> np.ndarray:
    """(p,) bool: is the line of sight from ``camera``'s centre to each point blocked?

    Parameters
    ----------
    camera : PinholeCamera
        Used for its centre and to cull triangles in its image (points outside it are
        reported as not occluded; test ``camera.in_view`` separately).
    points : (p, 3) float
        World points, mm.
    triangles : (T, 3, 3) float
        The occluding surfaces, world, mm.
    end_gap : float
        See :func:`segment_hits`.
    """
    points = np.asarray(points, float).reshape(-1, 3)
    tris = np.asarray(triangles, float).reshape(-1, 3, 3)
    out = np.zeros(len(points), bool)
    if len(points) == 0 or len(tris) == 0:
        return out
    # Boxes and points in the pinhole image (the camera without its lens distortion): a central
    # projection keeps straight lines straight, so a point whose line of sight crosses a triangle
    # projects inside that triangle's projection, and its box (1 px wider) holds it. Distorted
    # pixels would bend the triangle's edges out of the box of its corners; undistorted ones also
    # spare the distortion polynomial on every corner.
    uv = _pinhole(camera, tris.reshape(-1, 3)).reshape(-1, 3, 2)
    nan = np.isnan(uv)
    behind = nan.any(axis=(1, 2))  # a corner behind the camera: a box over everything
    uv[nan] = 0.0  # those boxes are replaced below
    c0, c1, c2 = uv[:, 0], uv[:, 1], uv[:, 2]
    lo = np.where(behind[:, None], -np.inf, np.minimum(np.minimum(c0, c1), c2) - 1.0)
    hi = np.where(behind[:, None], np.inf, np.maximum(np.maximum(c0, c1), c2) + 1.0)
    # points in the image (distorted pixels: what the camera sees) ...
    seen = camera.project(points)
    valid = np.isfinite(seen).all(axis=1) & camera.inside(seen, margin=-1.0)
    qi = np.flatnonzero(valid)
    if len(qi) == 0:
        return out
    q = _pinhole(camera, points[qi])
    # ... and only the triangles whose boxes meet the box of those points
    q_lo, q_hi = q.min(axis=0), q.max(axis=0)
    keep = np.flatnonzero((hi[:, 0] >= q_lo[0]) & (lo[:, 0] <= q_hi[0]) & (hi[:, 1] >= q_lo[1])
                          & (lo[:, 1] <= q_hi[1]))
    lo, hi = lo[keep].T.copy(), hi[keep].T.copy()
    pair_q, pair_t = _box_pairs(q, lo, hi)
    pair_q, pair_t = qi[pair_q], keep[pair_t]
    hit = segment_hits(np.broadcast_to(camera.center, (len(pair_q), 3)), points[pair_q], tris[pair_t],
                       end_gap)
    out[pair_q[hit]] = True
    return out
