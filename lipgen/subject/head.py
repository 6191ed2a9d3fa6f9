"""A head around the lips: the face proxy's relief (cheeks, chin, nasolabial folds) and a nose
with alae and nostrils, drawn per subject from a seed.

The face proxy of :class:`~lipgen.subject.face.FaceModel` is a set of rings from the lip mesh's
outer border out to an oval; its depth comes from :func:`face_depth`, a midline profile wrapped
round the cheeks. With a :class:`HeadShape` the depth gets the relief of a real lower face
(sizes from anthropometric ranges, Farkas 1994):

- nasolabial folds: creases 1-3 mm deep, 3-5 mm wide, running from beside the nose's alae down
  past the mouth corners (10-15 mm lateral of them);
- cheeks: malar fullness lateral of the folds, 3-7 mm high;
- chin: a mental protuberance 3-8 mm high below the lip mesh.

The proxy is then built finer (more rings, its border edges subdivided) so the folds are
resolved and cast real shadows. The nose (:func:`nose_mesh`) is the ellipsoid of the plain
face widened at the base into alae, with two nostrils: dark elliptical pits on its underside.
Its tip stays exactly the mesh's nose point.

How finely both are tessellated is a setting (``head_mesh``: the proxy's rings and border
subdivision, the nose's rings and sectors; :data:`HEAD_MESH` by default), measured per preset
against a finer mesh at the frame's scale (:mod:`lipgen.bench.preset_fidelity`). At 640 x 480
the default mesh's triangles cover a median 2-4 px (face) and 0.7-1.1 px (nose) in the two
views. A coarser nose has smaller nostrils, not only coarser ones (they are the faces whose
three corners lie in the pits; at 24 x 44 a quarter to two thirds of the dark area).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

__all__ = ["HeadShape", "head_shape", "face_depth", "build_proxy", "nose_mesh", "ellipsoid", "PROXY",
           "HEAD_MESH"]

# face profile: depth of the face surface at the midline against height (mm, model frame)
_PROFILE_Y = np.array([-95, -80, -68, -50, -30, 0, 20, 35, 55, 75, 100, 130.0])
_PROFILE_Z = np.array([-60, -30, -14, -10, -9, -4, -5, -8, -24, -26, -20, -30.0])
_CHEEK_RADIUS = 80.0  # mm, curvature of the face across x
# the nasolabial fold's course (|x|, y), mm, from beside the ala down past the mouth corner
_FOLD = np.array([[19.0, 27.0], [29.0, 19.0], [36.0, 7.0], [40.0, -6.0], [42.0, -20.0], [42.0, -32.0]])

PROXY = {"plain": (10, 1), "head": (28, 4)}
"""Rings and border subdivision of the face proxy: plain (today's) and with a head."""
_NOSE = (36, 64)  # rings and sectors of the head's nose (the default mesh)
HEAD_MESH = (*PROXY["head"], *_NOSE)
"""The head's default tessellation: (proxy rings, border subdivision, nose rings, nose sectors)."""


@dataclass(frozen=True)
class HeadShape:
    """One subject's head relief and nose, mm.

    Attributes
    ----------
    fold_depth, fold_width : float
        Depth and half width (Gaussian) of the nasolabial creases.
    cheek : float
        Height of the malar fullness lateral of the folds.
    chin : float
        Height of the mental protuberance.
    ala_width : float
        Half width of the nose at its alae.
    nostril : float
        Semi-major axis of each nostril (along the nose), mm.
    """

    fold_depth: float = 2.0
    fold_width: float = 4.0
    cheek: float = 5.0
    chin: float = 5.0
    ala_width: float = 16.0
    nostril: float = 5.0

    def to_dict(self) -> dict:
        """The shape as a JSON-ready dict (as stored in the manifest)."""
        return asdict(self)


def head_shape(seed) -> HeadShape:
    """A subject's :class:`HeadShape` drawn from ``seed`` (int or Generator) within published ranges."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(size=6)
    return HeadShape(fold_depth=1.0 + 2.0 * u[0], fold_width=3.0 + 2.0 * u[1], cheek=3.0 + 4.0 * u[2],
                     chin=3.0 + 5.0 * u[3], ala_width=14.5 + 4.0 * u[4], nostril=4.0 + 2.0 * u[5])


def _polyline_distance(p: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Distance of 2-D points ``p`` (..., 2) to the polyline ``line`` (m, 2)."""
    best = np.full(p.shape[:-1], np.inf)
    for a, b in zip(line[:-1], line[1:], strict=True):
        ab = b - a
        t = np.clip(((p - a) @ ab) / (ab @ ab), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(p - (a + t[..., None] * ab), axis=-1))
    return best


def face_depth(x, y, shape: HeadShape | None = None) -> np.ndarray:
    """Depth (z, mm) of the face surface at model-frame (x, y): the midline profile wrapped round the
    cheeks, plus, with a ``shape``, the folds, cheeks and chin."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    z = np.interp(y, _PROFILE_Y, _PROFILE_Z) - _CHEEK_RADIUS + np.sqrt(
        np.clip(_CHEEK_RADIUS**2 - x**2, 0.0, None))
    if shape is None:
        return z
    p = np.stack([np.abs(x), y], -1)
    d = _polyline_distance(p, _FOLD)
    fold = -shape.fold_depth * np.exp(-((d / shape.fold_width) ** 2))
    cheek = shape.cheek * np.exp(-(((np.abs(x) - 48.0) / 14.0) ** 2 + ((y - 12.0) / 18.0) ** 2))
    chin = shape.chin * np.exp(-((x / 20.0) ** 2 + ((y + 56.0) / 13.0) ** 2))
    return z + fold + cheek + chin


def build_proxy(border: np.ndarray, outer_axes, outer_y0: float, rings: int, subdiv: int, depth):
    """Rings of skin from a closed border loop out to an oval (the face proxy's rest geometry).

    Parameters
    ----------
    border : (k, 3) float
        The lip mesh's outer border, counter-clockwise seen from the front.
    outer_axes : (2,) float
        Semi-axes (x, y) of the outer oval, mm; centred at (0, ``outer_y0``).
    rings, subdiv : int
        Rings beyond the border, and points per border edge on each ring (1: the border's own).
    depth : callable
        ``depth(x, y)`` of the face surface.

    Returns
    -------
    dict
        ``rest`` (r, 3) vertices beyond the lip mesh (the border's inserted points first), ``col``
        (r,) their column (0..k*subdiv-1) round the loop, ``fade`` (r,) how much they follow the
        border's motion, ``weights`` (k*subdiv, k) border interpolation, ``ids`` (rings + 1,
        k*subdiv) indices into [lip vertices; rest] (offset by the lip mesh's size by the caller:
        lip vertex j is ``-1 - j``), ``s`` (rings,) ring positions in [0, 1].
    """
    k = len(border)
    K = k * subdiv
    t = (np.arange(K) % subdiv) / subdiv
    j = np.arange(K) // subdiv
    W = np.zeros((K, k))
    W[np.arange(K), j] = 1 - t
    W[np.arange(K), (j + 1) % k] += t
    b = border if subdiv == 1 else W @ border
    c = b[:, :2].mean(axis=0)
    d = b[:, :2] - c
    if (np.linalg.norm(d, axis=1) == 0).any():
        raise ValueError("the lip mesh border passes through its own centre; cannot build a face proxy")
    scale = np.maximum(np.asarray(outer_axes, float), 1.6 * np.abs(b[:, :2] - [0.0, outer_y0]).max(axis=0))
    q = (c - [0.0, outer_y0]) / scale
    dd = d / scale
    qa, qb, qc = np.sum(dd * dd, axis=1), 2 * dd @ q, q @ q - 1.0
    lam = (-qb + np.sqrt(qb * qb - 4 * qa * qc)) / (2 * qa)
    outer = c + lam[:, None] * d
    s = (np.arange(1, rings + 1) / rings) ** 1.6
    xy = b[None, :, :2] + s[:, None, None] * (outer - b[:, :2])[None]
    resid = b[:, 2] - depth(b[:, 0], b[:, 1])
    z = depth(xy[..., 0], xy[..., 1]) + resid[None] * ((1 - s) ** 3)[:, None]
    ring_pts = np.concatenate([xy, z[..., None]], axis=-1).reshape(-1, 3)
    extra = np.flatnonzero(t > 0)  # the border's inserted points (none without subdivision)
    fade = np.clip(1 - s / 0.5, 0, None) ** 2
    ids = np.empty((rings + 1, K), np.int64)
    ids[0] = -1 - j
    ids[0, extra] = np.arange(len(extra))
    ids[1:] = len(extra) + np.arange(rings * K).reshape(rings, K)
    col = np.concatenate([extra, np.tile(np.arange(K), rings)])
    return {"rest": np.vstack([b[extra], ring_pts]), "col": col,
            "fade": np.concatenate([np.ones(len(extra)), np.repeat(fade, K)]), "weights": W, "ids": ids,
            "s": s}


def ellipsoid(center, axes, n_rings: int = 12, n_sectors: int = 24, cap: float = np.pi):
    """Vertices, faces and normals of an ellipsoid whose pole ``center + a0`` is vertex 0.

    ``axes`` (3, 3) rows are the semi-axis vectors: the first points to the pole; ``cap`` is the
    polar angle where the surface stops (pi: closed).
    """
    a0, a1, a2 = axes
    theta = cap * np.arange(1, n_rings + 1) / n_rings
    phi = 2 * np.pi * np.arange(n_sectors) / n_sectors
    ct, st = np.cos(theta)[:, None, None], np.sin(theta)[:, None, None]
    ring = ct * a0 + st * (np.cos(phi)[None, :, None] * a1 + np.sin(phi)[None, :, None] * a2)
    V = np.vstack([center + a0, center + ring.reshape(-1, 3)])
    s = np.arange(n_sectors)
    s1 = (s + 1) % n_sectors
    F = [np.stack([np.zeros(n_sectors, np.int64), 1 + s1, 1 + s], 1)]
    for k in range(n_rings - 1):
        a, b = 1 + k * n_sectors + s, 1 + k * n_sectors + s1
        F += [np.stack([a, b + n_sectors, a + n_sectors], 1), np.stack([a, b, b + n_sectors], 1)]
    F = np.vstack(F)
    M = np.linalg.inv(np.stack([a0, a1, a2], 1))
    N = (V - center) @ M.T @ M  # gradient of the quadric: the outward normal
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    tri = V[F]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    if np.sum(fn * N[F].sum(axis=1)) < 0:  # wind the faces counter-clockwise seen from outside
        F = F[:, ::-1]
    return V, F, N


def nose_mesh(tip: np.ndarray, shape: HeadShape, rings: int = _NOSE[0], sectors: int = _NOSE[1]):
    """The nose: ``(vertices (n, 3), faces (m, 3), face_nostril (m,) bool)`` in the model frame.

    An ellipsoid (as the plain face's nose) whose tip vertex 0 is ``tip``, widened towards its base
    into alae of half width ``shape.ala_width``, with two nostrils on the underside pushed 2.5 mm
    into the nose, tessellated by ``rings`` x ``sectors``. Normals are left to the caller
    (area-weighted).
    """
    d = np.array([0.0, -0.25, 1.0])
    d /= np.linalg.norm(d)
    dorsum = np.array([0.0, 0.94, -0.34])
    ex = np.array([1.0, 0, 0])
    axes = np.stack([13.0 * d, 22.0 * dorsum, 11.0 * ex])
    center = tip - 13.0 * d
    V, F, _ = ellipsoid(center, axes, rings, sectors)
    rel = V - center
    a = rel @ d / 13.0  # 1 at the tip, -1 at the back
    h = rel @ dorsum / 22.0  # -1 at the base (columella side), +1 up the bridge
    x = rel @ ex
    # alae: widen the lower back half sideways
    wing = np.clip(-h, 0, 1) * np.clip(1 - a, 0, 1)
    V = V + ((shape.ala_width / 11.0 - 1.0) * wing)[:, None] * x[:, None] * ex[None]
    # nostrils: ellipses on the underside, either side of the columella
    u = (a - 0.15) / (shape.nostril / 13.0)
    w = (np.abs(x) - 0.45 * shape.ala_width) / (0.28 * shape.ala_width)
    r2 = u**2 + w**2
    under = h < -0.55
    pit = np.where(under & (r2 < 1.0), 2.5 * (1 - r2), 0.0)
    V = V + pit[:, None] * dorsum[None]
    V[0] = tip
    nostril = (pit[F] > 0.4).all(axis=1)
    return V, F, nostril
