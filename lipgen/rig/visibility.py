"""Ray casting against triangle soups: which points a camera sees (occlusion by surfaces).

The dataset's visibility truth comes from here, not from the renderer, so it is exact geometry
and independent of the rasteriser. A 2-D grid over the image culls the triangles a line of
sight could cross before the exact Moller-Trumbore test.
"""

from __future__ import annotations

import numpy as np

from lipgen.rig.pinhole import PinholeCamera

__all__ = ["segment_hits", "occluded"]

_CELL_PX = 12.0


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
    d = targets - origins
    length = np.linalg.norm(d, axis=1)
    A, B, C = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    e1, e2 = B - A, C - A
    p = np.cross(d, e2)
    det = np.sum(e1 * p, axis=1)
    ok = np.abs(det) > 1e-12 * np.maximum(length, 1.0) ** 3
    inv = np.divide(1.0, det, out=np.zeros_like(det), where=ok)
    s = origins - A
    u = np.sum(s * p, axis=1) * inv
    q = np.cross(s, e1)
    v = np.sum(d * q, axis=1) * inv
    t = np.sum(e2 * q, axis=1) * inv
    gap = end_gap / np.maximum(length, 1e-300)
    return ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > gap) & (t < 1 - gap)


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
    nx = int(np.ceil((camera.width + 2) / _CELL_PX))
    ny = int(np.ceil((camera.height + 2) / _CELL_PX))
    # triangles: pixel bounding boxes (behind-camera vertices make a box over the whole image)
    uv = camera.project(tris.reshape(-1, 3)).reshape(-1, 3, 2)
    behind = np.isnan(uv).any(axis=(1, 2))
    lo = np.where(behind[:, None], -np.inf, np.nanmin(uv, axis=1) - 1.0)
    hi = np.where(behind[:, None], np.inf, np.nanmax(uv, axis=1) + 1.0)
    c_lo = np.clip(np.floor((lo + 1.0) / _CELL_PX), 0, [nx - 1, ny - 1]).astype(np.int64)
    c_hi = np.clip(np.floor((hi + 1.0) / _CELL_PX), 0, [nx - 1, ny - 1]).astype(np.int64)
    off_image = (hi[:, 0] < -1) | (hi[:, 1] < -1) | (lo[:, 0] > camera.width) | (lo[:, 1] > camera.height)
    keep = np.flatnonzero(~off_image)
    c_lo, c_hi = c_lo[keep], c_hi[keep]
    span = c_hi - c_lo + 1
    count = span[:, 0] * span[:, 1]
    tri_id = np.repeat(keep, count)
    k = np.arange(len(tri_id)) - np.repeat(np.cumsum(count) - count, count)
    sx = np.repeat(span[:, 0], count)
    cell = (np.repeat(c_lo[:, 1], count) + k // sx) * nx + np.repeat(c_lo[:, 0], count) + k % sx
    order = np.argsort(cell, kind="stable")
    cell, tri_id = cell[order], tri_id[order]
    # points: their cell, then every (point, candidate triangle) pair
    q = camera.project(points)
    valid = np.isfinite(q).all(axis=1) & camera.inside(q, margin=-1.0)
    qi = np.flatnonzero(valid)
    qc = np.floor((q[qi] + 1.0) / _CELL_PX).astype(np.int64)
    qcell = np.clip(qc[:, 1], 0, ny - 1) * nx + np.clip(qc[:, 0], 0, nx - 1)
    start = np.searchsorted(cell, qcell, side="left")
    stop = np.searchsorted(cell, qcell, side="right")
    n_pairs = stop - start
    pair_q = np.repeat(qi, n_pairs)
    pair_t = tri_id[np.repeat(start, n_pairs) + np.arange(n_pairs.sum()) - np.repeat(
        np.cumsum(n_pairs) - n_pairs, n_pairs)]
    hit = segment_hits(np.broadcast_to(camera.center, (len(pair_q), 3)), points[pair_q], tris[pair_t],
                       end_gap)
    np.logical_or.at(out, pair_q[hit], True)
    return out
