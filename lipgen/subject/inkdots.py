"""Ink dots at surface points of the truth subject, not at the model's marker nodes.

A person's dots are drawn by hand: each lands near, never exactly on, the point the model calls
that marker. :func:`place_dots` puts dot k on the truth's rest surface (vermilion faces), 1-2 mm
from where the model's marker k lands once the model is registered onto the subject (a
similarity fit of the model's nodes onto the same anatomical nodes of the subject), measured
along the surface from that point's foot on it, in a direction and at a distance drawn per
subject (so the 3D distance is at least 1 mm, more where the shapes differ). A dot is stored
as a face and barycentric coordinates, so it rides on the deforming surface; its truth is that surface point
(:func:`dot_positions`), not any node. No two dots are closer than :data:`DOT_SEPARATION_MM`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lipgen.mesh.lipmesh import LipMesh

__all__ = ["SurfaceDots", "place_dots", "dot_positions", "closest_points", "similarity_fit",
           "DOT_OFFSET_MM", "DOT_SEPARATION_MM"]

DOT_OFFSET_MM = (1.0, 2.0)
"""Range of a dot's distance (mm) from the registered model marker."""

DOT_SEPARATION_MM = 3.0
"""Least distance (mm) between two dots' centres: a 2 mm dot plus 1 mm of bare skin. Drawn
without it, 15 of 40 subjects (seeds 0-39) had two dots overlapping (centres under 2 mm apart;
``upper_mid`` and ``bow_dip``, 2.65 mm apart on the model, in 14 of them; subject 0, the
``default`` preset's, 0.92 mm): one ink blob labelled as two markers, which no one drawing dots
on a face would make and no tracker can take apart."""


@dataclass(frozen=True, eq=False)
class SurfaceDots:
    """Dots on a triangle mesh: ``face`` (k,) int and ``bary`` (k, 3) float barycentric coordinates."""

    face: np.ndarray
    bary: np.ndarray

    def to_dict(self) -> dict:
        """The dots as a JSON-ready dict (as stored in the manifest)."""
        return {"face": self.face.tolist(), "bary": self.bary.tolist()}

    @classmethod
    def from_dict(cls, d: dict, n_faces: int | None = None) -> SurfaceDots:
        """Dots from a manifest's dict (written by :meth:`to_dict`), checked against the mesh."""
        face = np.asarray(d["face"], np.int64)
        bary = np.asarray(d["bary"], float)
        if face.ndim != 1 or bary.shape != (len(face), 3):
            raise ValueError(f"dots need face (k,) and bary (k, 3); got {face.shape} and {bary.shape}")
        if n_faces is not None and ((face < 0) | (face >= n_faces)).any():
            raise ValueError(f"dot faces must index the mesh's {n_faces} faces, got range "
                             f"[{face.min()}, {face.max()}]")
        if not np.allclose(bary.sum(axis=1), 1.0, atol=1e-9) or (bary < -1e-9).any():
            raise ValueError("dot barycentric coordinates must be >= 0 and sum to 1 per dot")
        return cls(face, bary)


def dot_positions(dots: SurfaceDots, faces: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """(..., k, 3) dot positions on ``vertices`` (..., n, 3) (any number of frames)."""
    V = np.asarray(vertices, float)
    tri = V[..., faces[dots.face], :]  # (..., k, 3, 3)
    return np.einsum("kj,...kjd->...kd", dots.bary, tri)


def similarity_fit(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Least-squares ``s, R, t`` with ``dst ~ s R src + t`` (Umeyama 1991); src, dst (n, 3)."""
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - mu_s, dst - mu_d
    U, S, Vt = np.linalg.svd(b.T @ a)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    s = float(np.trace(np.diag(S) @ D) / np.sum(a * a))
    return s, R, mu_d - s * R @ mu_s


def closest_points(points: np.ndarray, tri: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closest point of each of ``points`` (p, 3) on the triangles ``tri`` (t, 3, 3).

    Returns the triangle index (p,), barycentric coordinates (p, 3) and the points (p, 3)
    (the exact point-triangle distance, Ericson's region tests, vectorised over all pairs).
    """
    P = np.asarray(points, float)[:, None, :]
    A, B, C = tri[None, :, 0], tri[None, :, 1], tri[None, :, 2]
    ab, ac, ap = B - A, C - A, P - A
    d1, d2 = np.sum(ab * ap, -1), np.sum(ac * ap, -1)
    bp, cp = P - B, P - C
    d3, d4 = np.sum(ab * bp, -1), np.sum(ac * bp, -1)
    d5, d6 = np.sum(ab * cp, -1), np.sum(ac * cp, -1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = 1.0 / (va + vb + vc)
        v, w = vb * denom, vc * denom  # inside the face
        cand = [
            (d1 <= 0) & (d2 <= 0), (d3 >= 0) & (d4 <= d3), (d6 >= 0) & (d5 <= d6),
            (vc <= 0) & (d1 >= 0) & (d3 <= 0), (vb <= 0) & (d2 >= 0) & (d6 <= 0),
            (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0),
        ]
        t_ab, t_ac = d1 / (d1 - d3), d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    bary = np.stack([1 - v - w, v, w], -1)
    choices = [(1, 0, 0), (0, 1, 0), (0, 0, 1)]
    edge = [np.stack([1 - t_ab, t_ab, 0 * t_ab], -1), np.stack([1 - t_ac, 0 * t_ac, t_ac], -1),
            np.stack([0 * t_bc, 1 - t_bc, t_bc], -1)]
    for k in (5, 4, 3):  # edges, then vertices (later ones win, as in Ericson's order)
        bary = np.where(cand[k][..., None], edge[k - 3], bary)
    for k in (2, 1, 0):
        bary = np.where(cand[k][..., None], np.array(choices[k], float), bary)
    bary = np.nan_to_num(bary, nan=1.0 / 3)
    Q = np.einsum("ptj,tjd->ptd", bary, tri)
    dist = np.linalg.norm(Q - P, axis=-1)
    best = np.argmin(dist, axis=1)
    rows = np.arange(len(best))
    return best, bary[rows, best], Q[rows, best]


def _outer_faces(mesh: LipMesh) -> np.ndarray:
    """The faces ink can be drawn on: the vermilion and the skin (not the ridge rolling into the mouth)."""
    ids = [mesh.region_names.index(r) for r in ("lip", "skin") if r in mesh.region_names]
    faces = np.flatnonzero(np.isin(mesh.regions, ids))
    return faces if len(faces) else np.arange(mesh.n_faces)


def place_dots(truth: LipMesh, model: LipMesh, rng, offset_mm=DOT_OFFSET_MM,
               separation_mm: float = DOT_SEPARATION_MM) -> SurfaceDots:
    """Dots on ``truth``'s rest surface near ``model``'s markers (see the module docstring).

    Parameters
    ----------
    truth : LipMesh
        The subject's rest mesh; its first ``model.n_nodes`` nodes are the model's nodes'
        anatomical counterparts (as :func:`lipgen.subject.shape.shaped_mesh` keeps them).
    model : LipMesh
        The reconstruction model's mesh (its markers name the dots).
    rng : int or numpy.random.Generator
        Draws each dot's direction and distance.
    offset_mm : (float, float)
        Range of each dot's distance from the registered model marker, mm.
    separation_mm : float
        Least distance between the centres of two dots, mm (:data:`DOT_SEPARATION_MM`); a dot
        drawn nearer an earlier one is drawn again.

    Returns
    -------
    SurfaceDots
        One dot per model marker, in the model's marker order.
    """
    lo, hi = (float(v) for v in offset_mm)
    if not 0 <= lo <= hi <= 5:
        raise ValueError(f"offset_mm must be (low, high) with 0 <= low <= high <= 5 mm, got {offset_mm}")
    n0 = model.n_nodes
    if truth.n_nodes < n0:
        raise ValueError(f"the truth mesh has {truth.n_nodes} nodes, fewer than the model's {n0}")
    rng = np.random.default_rng(rng)
    s, R, t = similarity_fit(model.vertices, truth.vertices[:n0])
    goal = s * model.vertices[model.markers] @ R.T + t  # the model's markers on the subject
    faces = _outer_faces(truth)
    tri = truth.vertices[truth.faces[faces]]
    _, _, foot = closest_points(goal, tri)
    # a tangent direction at the foot: the surface normal from the nearest face
    fi, _, _ = closest_points(foot, tri)
    n = np.cross(tri[fi, 1] - tri[fi, 0], tri[fi, 2] - tri[fi, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    e1 = np.cross(n, np.array([0.0, 0.0, 1.0]))
    e1 /= np.maximum(np.linalg.norm(e1, axis=1, keepdims=True), 1e-12)
    e2 = np.cross(n, e1)
    sep = float(separation_mm)
    if not (np.isfinite(sep) and sep >= 0):
        raise ValueError(f"separation_mm must be a distance >= 0 mm, got {separation_mm!r}")
    k = len(goal)
    for _ in range(20):  # a dot hemmed in by earlier ones: the whole layout is drawn again
        out_f, out_b, placed = np.zeros(k, np.int64), np.zeros((k, 3)), np.zeros((0, 3))
        for i in range(k):
            for _ in range(100):  # redraw until the dot lands in range (the surface curves away), apart
                r, phi = rng.uniform(lo, hi), rng.uniform(0, 2 * np.pi)
                target = foot[i] + r * (np.cos(phi) * e1[i] + np.sin(phi) * e2[i])
                f, b, q = closest_points(target[None], tri)
                if lo - 1e-9 <= np.linalg.norm(q[0] - foot[i]) <= hi + 1e-9 and (
                        len(placed) == 0 or np.linalg.norm(placed - q[0], axis=1).min() >= sep):
                    break
            else:
                break
            out_f[i], out_b[i] = faces[f[0]], b[0]
            placed = np.vstack([placed, q])
        if len(placed) == k:
            return SurfaceDots(out_f, out_b)
    raise ValueError(f"cannot place dot {model.marker_names[len(placed)]!r} {lo}-{hi} mm from the model's "
                     f"marker and {sep} mm from the other dots on the subject's lips (the surface there is "
                     "too small)")
