"""The thin-shell triangle of Basu 1997, §2.3 (eqs 2.9-2.14), vectorised over faces.

Each triangle is worked in its own local frame: î along edge 1->2, k̂ the unit normal (right-hand
rule over the node order), ĵ = k̂ × î; λ = [î; ĵ; k̂] maps global to local and
T = blockdiag(λ, λ, λ). In that frame the element is two decoupled parts:

* ``k_xy`` (6 x 6): the plane-strain constant-strain triangle (CST), ``A · Bᵀ C B`` with the
  material matrix C of eq 2.12. The thickness is taken as 1 (the thesis gives none); since E is a
  relative stiffness anyway, a thickness would only rescale every E.
* ``k_z`` (3 x 3): eq 2.13, ``E' [[1, -.5, -.5], [-.5, 1, -.5], [-.5, -.5, 1]]`` with
  ``E' = E (1 - ν) / ((1 + ν)(1 - 2ν))``, the prefactor of eq 2.12.

They are interleaved into x, y, z order per node (eq 2.14) and rotated to the global frame,
``k' = Tᵀ k T`` (eq 2.7). E is per face and scales the whole element.

On ``k_z`` as printed (no area factor)
---------------------------------------
Eq 2.13 has no length in it: an element's out-of-plane stiffness does not depend on its size or
shape. Its energy is ``E'/2 · Σ_edges (w_i - w_j)²``, a graph Laplacian with unit edge weights:
a membrane under tension, not a plate (there is no bending stiffness, and an out-of-plane tilt
of one element costs energy, so rigid rotations of a *curved* mesh are not free).

Does that need an area factor for mesh-refinement consistency? No. The 2-D CST ``k_xy`` with
unit thickness is itself size-independent (B ~ 1/L, A ~ L²), and so is the continuum membrane
energy ∫|∇w|² dA discretised on P1 triangles (the cotangent Laplacian). Multiplying ``k_z`` by
the area would make the out-of-plane stiffness vanish like h² under refinement while the in-plane
stiffness stays put. What the printed form does lack is *shape* awareness: every edge weighs the
same whatever the triangle's angles, so on an irregular or stretched mesh the effective membrane
tension is anisotropic and depends on how the surface was triangulated (under uniform midpoint
refinement each child is similar to its parent, so it still converges, but to a limit that depends
on the triangle shapes). The option ``out_of_plane="laplacian"`` replaces eq 2.13 by the P1
membrane stiffness ``√3 · E' · A · ∇Nᵢ·∇Nⱼ``, which equals eq 2.13 *exactly* on an equilateral
triangle and is consistent on any triangulation. The thesis's form stays the default.

Measured (``tests/test_fem_physics.py``): a square sheet with held edges under uniform pressure,
refined 8 -> 64 cells per side. The ``"laplacian"`` form converges to the closed-form membrane
deflection for tension ``T = √3 E'`` (0.2% off at 32 cells). Eq 2.13 also converges, but on these
right-isosceles triangles to the deflection of ``T = 2 E'``: the same element is 15% stiffer out
of plane on this mesh than on an equilateral one.
"""

from __future__ import annotations

import numpy as np

from lipgen._validate import as_float_array
from lipgen.errors import MeshError
from lipgen.tol import tol

__all__ = ["OUT_OF_PLANE", "element_frames", "element_stiffness", "material_factor"]

OUT_OF_PLANE: tuple[str, ...] = ("thesis", "laplacian")
"""Forms of the out-of-plane block: eq 2.13 as printed, or the shape-aware P1 membrane."""



def material_factor(E, nu: float) -> np.ndarray:
    """``E (1 - ν) / ((1 + ν)(1 - 2ν))``, the prefactor of eqs 2.12 and 2.13."""
    return np.asarray(E, float) * (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu))


def element_frames(tri: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Local frames and in-plane coordinates of triangles.

    Parameters
    ----------
    tri : (m, 3, 3) float
        Node positions of each triangle (node, xyz), mm.

    Returns
    -------
    lam : (m, 3, 3) float
        Rows î, ĵ, k̂ (eq 2.5): ``lam @ v`` maps a global vector to local coordinates.
    xy : (m, 3, 2) float
        Local in-plane coordinates of the three nodes (node 1 at the origin, node 2 on +x).
    area : (m,) float
        Triangle areas, mm².
    """
    tri = as_float_array(tri, "tri", (None, 3, 3))
    e1 = tri[:, 1] - tri[:, 0]
    e2 = tri[:, 2] - tri[:, 0]
    nrm = np.cross(e1, e2)
    twice_area = np.linalg.norm(nrm, axis=1)
    len1 = np.linalg.norm(e1, axis=1)
    scale = np.maximum(np.maximum(len1, np.linalg.norm(e2, axis=1)), 1.0)
    bad = twice_area <= 2.0 * tol.area * scale**2
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise MeshError(f"{int(bad.sum())} degenerate (zero-area) triangle(s), e.g. number {i} with "
                        f"nodes {tri[i].tolist()}; the element needs a proper triangle")
    i_hat = e1 / len1[:, None]
    k_hat = nrm / twice_area[:, None]
    j_hat = np.cross(k_hat, i_hat)
    lam = np.stack([i_hat, j_hat, k_hat], axis=1)
    xy = np.zeros((len(tri), 3, 2))
    xy[:, 1, 0] = len1
    xy[:, 2, 0] = np.einsum("mi,mi->m", e2, i_hat)
    xy[:, 2, 1] = np.einsum("mi,mi->m", e2, j_hat)
    return lam, xy, 0.5 * twice_area


def _shape_gradients(xy: np.ndarray, area: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(m, 3) dN/dx and dN/dy of the linear shape functions (Zienkiewicz's b_i, c_i over 2A)."""
    x, y = xy[..., 0], xy[..., 1]
    b = np.stack([y[:, 1] - y[:, 2], y[:, 2] - y[:, 0], y[:, 0] - y[:, 1]], axis=1)
    c = np.stack([x[:, 2] - x[:, 1], x[:, 0] - x[:, 2], x[:, 1] - x[:, 0]], axis=1)
    return b / (2 * area[:, None]), c / (2 * area[:, None])


def _strain_displacement(xy: np.ndarray, area: np.ndarray) -> np.ndarray:
    """(m, 3, 6) B of eq 2.2 for the strains of eq 2.10 over ``(u1, v1, u2, v2, u3, v3)``."""
    dx, dy = _shape_gradients(xy, area)
    B = np.zeros((len(xy), 3, 6))
    B[:, 0, 0::2] = dx
    B[:, 1, 1::2] = dy
    B[:, 2, 0::2] = dy
    B[:, 2, 1::2] = dx
    return B


_KZ_ROOT = np.sqrt(1.5) * np.array([[1.0, -1.0, 0.0], [1.0, 1.0, -2.0]]) / np.sqrt([[2.0], [6.0]])
"""W (2 x 3) with WᵀW = eq 2.13's matrix (1.5 I - 0.5 11ᵀ): its range is the complement of 1."""


def _inplane_factor(G: np.ndarray, area: np.ndarray, Ep: np.ndarray, nu: float) -> np.ndarray:
    """(m, 3, 9) H with HᵀH = A Gᵀ C G (eq 2.12's C = E' C0, C0 = Σ λ v vᵀ over its eigenpairs)."""
    r, s = nu / (1.0 - nu), (1 - 2 * nu) / (2 * (1 - nu))
    g0, g1, g2 = G[:, 0], G[:, 1], G[:, 2]
    H = np.stack([np.sqrt((1 + r) / 2) * (g0 + g1), np.sqrt((1 - r) / 2) * (g0 - g1), np.sqrt(s) * g2],
                 axis=1)
    return H * np.sqrt(area * Ep)[:, None, None]


def _outplane_root(xy: np.ndarray, area: np.ndarray, Ep: np.ndarray, form: str) -> np.ndarray:
    """(m, 2, 3) M with MᵀM = k_z: eq 2.13 (``"thesis"``) or the P1 membrane (``"laplacian"``)."""
    if form == "thesis":
        return np.sqrt(Ep)[:, None, None] * _KZ_ROOT
    dx, dy = _shape_gradients(xy, area)
    return np.sqrt(np.sqrt(3.0) * Ep * area)[:, None, None] * np.stack([dx, dy], axis=1)


def _check_E(E, m: int) -> np.ndarray:
    E = as_float_array(E, "E")
    if E.ndim == 0:
        E = np.full(m, float(E))
    elif E.shape != (m,):
        raise ValueError(f"E must be a scalar or have shape ({m},) (one per face), got {E.shape}")
    if (E <= 0).any():
        i = int(np.flatnonzero(E <= 0)[0])
        raise ValueError(f"E must be positive for every face, got E[{i}] = {E[i]!r} (E has shape {E.shape})")
    return E


def element_stiffness(tri, E, nu: float = 0.01, out_of_plane: str = "thesis") -> np.ndarray:
    """Global-frame stiffness of thin-shell triangles (eqs 2.9-2.14 and 2.7).

    Parameters
    ----------
    tri : (m, 3, 3) float
        Node positions of each triangle, mm.
    E : float or (m,) float
        Relative elastic modulus of each face (> 0); scales the whole element.
    nu : float
        Poisson's ratio, in [0, 0.5). The thesis uses 0.01.
    out_of_plane : {"thesis", "laplacian"}
        Eq 2.13 as printed (default), or its shape-aware variant (see the module docstring).

    Returns
    -------
    (m, 9, 9) float
        Symmetric PSD element matrices over ``(x1, y1, z1, x2, y2, z2, x3, y3, z3)``.

    Notes
    -----
    ``Tᵀ k T`` with the interleaved k of eq 2.14 is evaluated without forming T. Because k has
    no in-plane/out-of-plane coupling, the (I, J) node block is
    ``Pᵀ k_xy[I, J] P + k_z[I, J] k̂ k̂ᵀ`` with ``P = [î; ĵ]`` (2 x 3): the in-plane part is
    ``A Gᵀ C G`` with the global strain-displacement matrix ``G = B · blockdiag(P, P, P)``, and
    the out-of-plane part acts on ``w_I = k̂ · u_I``. Both are written as ``JᵀJ`` with a 5 x 9
    J per face (3 rows from C's eigen-decomposition, 2 from k_z = MᵀM, eq 2.13 having rank 2),
    so each element matrix comes from one small product and is exactly symmetric and PSD. The
    tests check the result against the literal interleave-and-rotate construction.
    """
    if not 0.0 <= nu < 0.5:
        raise ValueError(f"Poisson's ratio nu must be in [0, 0.5), got {nu!r}")
    if out_of_plane not in OUT_OF_PLANE:
        raise ValueError(f"out_of_plane must be one of {OUT_OF_PLANE}, got {out_of_plane!r}")
    lam, xy, area = element_frames(tri)
    m = len(lam)
    E = _check_E(E, m)
    Ep = material_factor(E, nu)
    B = _strain_displacement(xy, area)  # (m, 3, 6)
    P = lam[:, :2, :]  # (m, 2, 3) rows î, ĵ
    G = (B.reshape(m, 3, 3, 2) @ P[:, None]).reshape(m, 3, 9)  # global strain-displacement
    M = _outplane_root(xy, area, Ep, out_of_plane)  # (m, 2, 3)
    N = (M[:, :, :, None] * lam[:, 2][:, None, None, :]).reshape(m, 2, 9)  # w_I = k̂ · u_I
    J = np.concatenate([_inplane_factor(G, area, Ep, nu), N], axis=1)  # (m, 5, 9)
    return J.transpose(0, 2, 1) @ J
