"""Ink dots that lie on a deforming triangle surface.

A dot is a small disc mesh laid on the rest surface: each of its vertices is projected along
the surface normal onto a triangle and stored by barycentric coordinates. On every frame it is
rebuilt from the deformed triangles, so the ink stretches with the skin, hugs the surface and
its centre stays exactly on the marked vertex (or surface point, :func:`make_decal_at`).
It is lifted by a few hundredths of a millimetre
along the surface normal so that the depth test draws it over the skin. All of a frame's dots
are drawn as one mesh (one draw call), their smudge halos as a second.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from lipgen.rig.scene import Material, MeshItem

__all__ = ["Decal", "make_decal", "make_decal_at", "place_decal"]


@dataclass(frozen=True, eq=False)
class Decal:
    """A disc fixed to a surface.

    Attributes
    ----------
    face : (k,) int
        Surface triangle of each decal vertex.
    bary : (k, 3) float
        Barycentric coordinates of each decal vertex in its triangle.
    faces : (f, 3) int
        The decal's own triangles (into its k vertices).
    rim : (r,) int
        Decal vertices on its outer edge (for partial-visibility tests).
    halo : (h, 3) int
        Triangles of a faint ring round the disc (ink spreading into the skin); empty unless
        laid with a ``halo``.
    """

    face: np.ndarray
    bary: np.ndarray
    faces: np.ndarray
    rim: np.ndarray
    halo: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int64))


def _disc(radius: float, rings: int, sectors: int, outline=None,
          halo: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Polar disc in its plane: points (k, 2), faces (f, 3) counter-clockwise, rim indices, and the
    faces of a halo ring ``halo * radius`` wider (none when 0). ``outline`` (sectors,) scales the
    radius per sector (an irregular edge)."""
    ang = 2 * np.pi * np.arange(sectors) / sectors
    r = radius * np.arange(1, rings + 1) / rings
    if halo > 0:
        r = np.append(r, radius * (1 + halo))
    unit = np.stack([np.cos(ang), np.sin(ang)], -1)
    if outline is not None:
        unit = unit * np.asarray(outline, float).reshape(sectors, 1)
    pts = np.vstack([[0.0, 0.0], (r[:, None, None] * unit[None]).reshape(-1, 2)])
    s = np.arange(sectors)
    s1 = (s + 1) % sectors
    faces = [np.stack([np.zeros(sectors, np.int64), 1 + s, 1 + s1], 1)]
    for k in range(len(r) - 1):
        a, b = 1 + k * sectors + s, 1 + k * sectors + s1
        c, d = a + sectors, b + sectors
        faces += [np.stack([a, c, d], 1), np.stack([a, d, b], 1)]
    faces = np.vstack(faces)
    n_ink = sectors * (2 * rings - 1)
    rim = 1 + (rings - 1) * sectors + s
    return pts, faces[:n_ink], rim, faces[n_ink:]


def _line_hits(q: np.ndarray, n: np.ndarray, tri: np.ndarray):
    """Lines ``q[i] + lam * n`` against triangles ``tri[j]``: (lam, u, v) of shape (i, j)."""
    A, B, C = tri[:, 0], tri[:, 1], tri[:, 2]
    e1, e2 = B - A, C - A
    p = np.cross(n, e2)
    det = e1 @ p if p.ndim == 1 else np.sum(e1 * p, axis=1)
    inv = np.divide(1.0, det, out=np.full_like(det, np.nan), where=np.abs(det) > 1e-14)
    s = q[:, None, :] - A[None]
    u = np.sum(s * p[None], axis=2) * inv
    qq = np.cross(s, e1[None])
    v = (qq @ n) * inv
    lam = np.sum(e2[None] * qq, axis=2) * inv
    return lam, u, v


def make_decal(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, center: int,
               radius: float, rings: int = 3, sectors: int = 16, outline=None, halo: float = 0.0) -> Decal:
    """Lay a disc of ``radius`` mm centred on vertex ``center`` of a rest surface.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int
    normals : (n, 3) float
        Unit vertex normals of the surface.
    center : int
        The marked vertex; the decal's centre maps exactly onto it.
    radius : float
        Disc radius, mm.
    outline : (sectors,) float, optional
        Radius factor per sector (an irregular edge); a circle by default.
    halo : float
        Width of a halo ring round the disc, as a fraction of ``radius`` (0: none).

    Raises
    ------
    ValueError
        If the surface around ``center`` is too small or folded to hold the disc's centre.
    """
    home = np.isin(faces, center).any(axis=1)
    return _lay(vertices, faces, vertices[center], normals[center], home, radius, rings, sectors,
                f"vertex {center}", outline=outline, halo=halo)


def make_decal_at(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, face: int, bary,
                  radius: float, rings: int = 3, sectors: int = 16, outline=None, halo: float = 0.0) -> Decal:
    """Lay a disc of ``radius`` mm centred on the surface point ``bary`` (3,) of triangle ``face``.

    As :func:`make_decal`, for a dot that is not at a vertex: its centre maps exactly onto that
    surface point on every frame.
    """
    b = np.asarray(bary, float)
    tri = faces[int(face)]
    p = b @ vertices[tri]
    n = b @ normals[tri]
    n = n / np.linalg.norm(n)
    home = np.zeros(len(faces), bool)
    home[int(face)] = True
    return _lay(vertices, faces, p, n, home, radius, rings, sectors, f"face {int(face)}", force_home=True,
                outline=outline, halo=halo)


def _lay(vertices, faces, p, n, home, radius, rings, sectors, where, force_home=False, outline=None,
         halo=0.0) -> Decal:
    e1 = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    pts2, dfaces, rim, hfaces = _disc(radius, rings, sectors, outline, halo)
    reach = radius * (1 + halo) * (1.0 if outline is None else max(1.0, float(np.max(outline))))
    q = p + pts2[:, :1] * e1 + pts2[:, 1:] * e2
    # candidate triangles: near the centre and facing the same way (not the opposite lip)
    tri = vertices[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-300)
    near = np.linalg.norm(tri - p, axis=2).min(axis=1) <= 2 * reach + 1.0
    facing = near & (fn @ n > 0.3)
    cand = np.flatnonzero(facing | (home if force_home else False))
    has_center = home[cand]
    if not has_center.any():
        raise ValueError(f"no surface triangle around {where} faces its normal; cannot place a dot")
    lam, u, v = _line_hits(q, n, tri[cand])
    eps = 1e-9
    inside = (u >= -eps) & (v >= -eps) & (u + v <= 1 + eps) & (np.abs(lam) <= reach)
    score = np.where(inside, np.abs(lam), np.inf)
    score[0] = np.where(has_center, score[0], np.inf)  # the centre lies on its own triangle
    best = np.argmin(score, axis=1)
    rows = np.arange(len(q))
    found = np.isfinite(score[rows, best])
    if not found[0]:
        raise ValueError(f"cannot place a dot at {where}: its own triangles are degenerate")
    uu, vv = u[rows, best], v[rows, best]
    bary = np.stack([1 - uu - vv, uu, vv], axis=1)
    face = cand[best]
    keep_faces = found[dfaces].all(axis=1)
    new_index = np.cumsum(found) - 1
    keep_halo = found[hfaces].all(axis=1)
    return Decal(face[found], bary[found], new_index[dfaces[keep_faces]], new_index[rim[found[rim]]],
                 new_index[hfaces[keep_halo]].reshape(-1, 3))


def place_decal(decal: Decal, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray,
                lift: float = 0.05) -> np.ndarray:
    """(k, 3) decal vertex positions on the (deformed) surface, lifted ``lift`` mm along its normal."""
    idx = faces[decal.face]
    pos = np.einsum("kj,kjd->kd", decal.bary, vertices[idx])
    nrm = np.einsum("kj,kjd->kd", decal.bary, normals[idx])
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
    return pos + lift * nrm


def _dots_items(dots: list, ink: tuple[Material, ...], lift: float, style, age: float) -> list[MeshItem]:
    """The ink dots as one mesh (one draw call), dot k with material ``ink[k]``; with a smudging
    ``style``, their halos as a second, translucent one."""
    if style is not None:
        ink = tuple(replace(m, color=style.ink_color(m.color, age)) for m in ink)
    items = [_dots_item(dots, ink, lift)]
    opacity = 0.0 if style is None else style.halo_opacity(age)
    if opacity > 0:
        halo = [(replace(d, faces=d.halo), V, F, N) for d, V, F, N in dots]
        mats = tuple(replace(m, name=f"smudge_{k}", opacity=opacity) for k, m in enumerate(ink))
        items.append(_dots_item(halo, mats, lift * 0.8, name="smudge"))
    return items


def _dots_item(dots: list, ink: tuple[Material, ...], lift: float, name: str = "dots") -> MeshItem:
    """All ink dots as one mesh (one draw call), dot k with material ``ink[k]``."""
    P, Fs, Ns, mats, offset = [], [], [], [], 0
    for k, (decal, V, F, N) in enumerate(dots):
        P.append(place_decal(decal, V, F, N, lift))
        nrm = np.einsum("kj,kjd->kd", decal.bary, N[F[decal.face]])
        Ns.append(nrm / np.linalg.norm(nrm, axis=1, keepdims=True))
        Fs.append(decal.faces + offset)
        mats.append(np.full(len(decal.faces), k))
        offset += len(P[-1])
    return MeshItem(name, np.vstack(P), np.vstack(Fs), ink[:len(dots)], np.concatenate(mats), np.vstack(Ns))
