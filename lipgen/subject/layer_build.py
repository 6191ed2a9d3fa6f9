"""Building the truth subject's tissue layer (:class:`~lipgen.subject.layer.Layer`) under a lip
surface: the surface extruded inwards by a per-node thickness into one layer of prisms, each split
into three tetrahedra, with per-face materials, the anchors, the gum springs and the lip contact
pairs, and the stiffness at rest."""

from __future__ import annotations

import numpy as np

from lipgen.subject.layer import Layer
from lipgen.subject.layer_stiffness import rest_stiffness

__all__ = ["build_layer"]


def _vertex_normals(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    n = np.zeros_like(V)
    for k in range(3):
        np.add.at(n, F[:, k], fn)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def _prism_tets(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(3m, 4) tetrahedra of the prisms over ``faces`` (inner copy of node i is i + n), split by
    global node order so neighbouring prisms share their diagonals; and each tet's face."""
    s = np.sort(faces, axis=1)
    i, j, k = s[:, 0], s[:, 1], s[:, 2]
    tets = np.concatenate([np.stack([i, j, k, k + n], 1), np.stack([i, j, j + n, k + n], 1),
                           np.stack([i, i + n, j + n, k + n], 1)])
    return tets, np.tile(np.arange(len(faces)), 3)


def build_layer(mesh, young: np.ndarray, thickness: np.ndarray, poisson: float = 0.45,
                kappa_ratio: float = 20.0, anchors=None, contact_pairs=None, contact_stiffness: float = 50.0,
                gum_nodes: np.ndarray | None = None, gum_stiffness: float = 5.0) -> Layer:
    """A :class:`Layer` under ``mesh``'s surface.

    Parameters
    ----------
    mesh : LipMesh
        The truth's rest surface; its face orientation gives the outward side (the layer goes the
        other way, into the tissue).
    young : (m,) float
        Young's modulus per face (the model's relative units).
    thickness : (n,) float
        Layer thickness under each node, mm.
    poisson : float
        Poisson's ratio of the StVK part (< 0.5).
    kappa_ratio : float
        Volume penalty as a multiple of the shear modulus (near-incompressibility).
    anchors : (a,) int, optional
        Surface nodes held (with their inner copies); ``mesh.anchors`` by default.
    contact_pairs : (p, 2) int, optional
        [upper, lower] surface node pairs kept from crossing in y.
    gum_nodes : (n,) float, optional
        Weight of each surface node's inner copy's spring to the jaw (0 .. 1).
    """
    V, Fc = mesh.vertices, mesh.faces
    n = len(V)
    young = np.broadcast_to(np.asarray(young, float), (len(Fc),))
    thickness = np.broadcast_to(np.asarray(thickness, float), (n,))
    if not 0 <= poisson < 0.5:
        raise ValueError(f"poisson must be in [0, 0.5), got {poisson}")
    if (thickness <= 0).any() or (young <= 0).any():
        raise ValueError("layer thickness and Young's modulus must be positive")
    N = _vertex_normals(V, Fc)
    rest = np.vstack([V, V - thickness[:, None] * N])
    tets, tface = _prism_tets(Fc, n)
    Dm = np.stack([rest[tets[:, k]] - rest[tets[:, 0]] for k in (1, 2, 3)], axis=-1)
    det = np.linalg.det(Dm)
    flip = det < 0
    tets[flip] = tets[flip][:, [0, 2, 1, 3]]
    Dm[flip] = Dm[flip][..., [1, 0, 2]]
    det = np.abs(det)
    if (det < 1e-12).any():
        raise ValueError("degenerate layer tetrahedra: the thickness is too small for the mesh")
    E = young[tface]
    mu = E / (2 * (1 + poisson))
    lam = E * poisson / ((1 + poisson) * (1 - 2 * poisson))
    fixed = np.zeros(2 * n, bool)
    a = mesh.anchors if anchors is None else np.asarray(anchors)
    fixed[a] = fixed[a + n] = True
    gum = np.zeros(2 * n)
    if gum_nodes is not None:
        gum[n:] = gum_stiffness * np.asarray(gum_nodes, float)
    pairs = np.zeros((0, 2), np.int64) if contact_pairs is None else np.asarray(contact_pairs, np.int64)
    Dm_inv, vol, kappa = np.linalg.inv(Dm), det / 6.0, kappa_ratio * mu
    # at rest the volume penalty adds kappa to lambda (d det F = tr dF)
    K0 = rest_stiffness(rest, tets, Dm_inv, vol, mu, lam + kappa, gum, pairs, float(contact_stiffness))
    return Layer(rest, tets, Dm_inv, vol, mu, lam, kappa, fixed, pairs, float(contact_stiffness), gum,
                 K0)
