"""The stiffness of the truth subject's tissue layer (:mod:`lipgen.subject.layer`).

Each tetrahedron's energy Hessian comes from the stress derivative ``dP/dF`` in closed form
(:func:`stress_derivative`), exact or its positive semi-definite part, mapped to the tet's 12 node
coordinates (:func:`tet_hessians`), and summed into a sparse matrix whose pattern is built once
(:class:`StiffnessPattern`). :func:`spd_solver` factorises it; :func:`rest_stiffness` is linear
elasticity at rest (the solver's first preconditioner, and the small-strain theory the tests use).
"""

from __future__ import annotations

import numpy as np

__all__ = ["deformation_gradients", "strain_state", "symmetric_eigenvalues", "positive_part",
           "stress_derivative", "tet_hessians", "StiffnessPattern", "fill_reducing_order", "spd_solver",
           "rest_stiffness"]

_LEVI_CIVITA = np.zeros((3, 3, 3))
for _i, _j, _k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
    _LEVI_CIVITA[_i, _j, _k], _LEVI_CIVITA[_i, _k, _j] = 1.0, -1.0
_COFACTOR_DERIVATIVE = np.einsum("ikn,jlq->nqijkl", _LEVI_CIVITA, _LEVI_CIVITA).reshape(9, 81)
"""d cof(F)_ij / dF_kl = eps_ikn eps_jlq F_nq, as a (9 [nq], 81 [ijkl]) matrix."""


def deformation_gradients(x: np.ndarray, tets: np.ndarray, Dm_inv: np.ndarray) -> np.ndarray:
    """(T, 3, 3) deformation gradient of each tet at node positions ``x`` (N, 3), with inverse rest
    edge matrices ``Dm_inv`` (T, 3, 3)."""
    P0 = x[tets[:, 0]]
    Ds = np.stack([x[tets[:, 1]] - P0, x[tets[:, 2]] - P0, x[tets[:, 3]] - P0], axis=-1)
    return Ds @ Dm_inv


def strain_state(F: np.ndarray, mu, lam):
    """The Green strain ``E`` (T, 3, 3), its trace (T,), the St Venant-Kirchhoff second
    Piola-Kirchhoff stress ``S`` (T, 3, 3), the cofactor matrix ``det(F) F^-T`` (T, 3, 3) and
    ``J = det F`` (T,) of deformation gradients ``F`` (T, 3, 3)."""
    E = 0.5 * (np.swapaxes(F, -1, -2) @ F - np.eye(3))
    trE = np.trace(E, axis1=-2, axis2=-1)
    S = 2 * mu[:, None, None] * E + (lam * trE)[:, None, None] * np.eye(3)
    f0, f1, f2 = F[..., 0], F[..., 1], F[..., 2]
    cof = np.stack([np.cross(f1, f2), np.cross(f2, f0), np.cross(f0, f1)], axis=-1)
    J = np.sum(f0 * cof[..., 0], axis=-1)
    return E, trE, S, cof, J


def symmetric_eigenvalues(A: np.ndarray) -> np.ndarray:
    """(T, 3) eigenvalues, descending, of symmetric 3 x 3 matrices ``A`` (T, 3, 3), in closed form.

    The trigonometric solution of the characteristic cubic (Smith 1961): LAPACK's ``eigh`` over
    thousands of 3 x 3 matrices spends most of its time in per-matrix calls. Accurate to about
    ``1e-8 |A|`` where eigenvalues nearly coincide (the cubic's double root), to rounding elsewhere.
    """
    q = np.trace(A, axis1=1, axis2=2) / 3.0
    off = A[:, 0, 1] ** 2 + A[:, 0, 2] ** 2 + A[:, 1, 2] ** 2
    dev = A - q[:, None, None] * np.eye(3)
    p = np.sqrt((np.sum(np.diagonal(dev, axis1=1, axis2=2) ** 2, axis=1) + 2.0 * off) / 6.0)
    safe = np.where(p > 0, p, 1.0)
    r = np.clip(np.linalg.det(dev / safe[:, None, None]) / 2.0, -1.0, 1.0)
    phi = np.arccos(r) / 3.0
    top = q + 2.0 * p * np.cos(phi)
    bottom = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
    return np.stack([top, 3.0 * q - top - bottom, bottom], axis=1)


def positive_part(S: np.ndarray) -> np.ndarray:
    """(T, 3, 3) positive part ``sum over lambda > 0 of lambda u u^T`` of symmetric 3 x 3 matrices
    ``S`` (T, 3, 3), without eigenvectors.

    From the eigenvalues ``l1 >= l2 >= l3`` (:func:`symmetric_eigenvalues`), by the spectral
    projector of the eigenvalue on the minority side of zero: with one positive eigenvalue the part
    is ``l1 (S - l2)(S - l3) / ((l1 - l2)(l1 - l3))``, with two it is ``S - l3 (S - l1)(S - l2) /
    ((l3 - l1)(l3 - l2))``. Each denominator is at least the square of the eigenvalue in front
    (the others lie across zero), so neither blows up; all positive gives ``S``, none gives 0.
    """
    lam = symmetric_eigenvalues(S)
    eye = np.eye(3)
    n_pos = (lam > 0).sum(axis=1)
    out = np.where((n_pos == 3)[:, None, None], S, 0.0)
    for count, lead, a, b in ((1, 0, 1, 2), (2, 2, 0, 1)):
        m = n_pos == count
        if not m.any():
            continue
        Sm, lm = S[m], lam[m]
        proj = ((Sm - lm[:, a, None, None] * eye) @ (Sm - lm[:, b, None, None] * eye)
                / ((lm[:, lead] - lm[:, a]) * (lm[:, lead] - lm[:, b]))[:, None, None])
        part = lm[:, lead, None, None] * proj
        out[m] = part if count == 1 else Sm - part
    return out


def stress_derivative(F: np.ndarray, mu, lam, kappa, psd: bool = False) -> np.ndarray:
    """(T, 9, 9) ``dP_ij / dF_kl`` (row-major ``ij``, ``kl``) of the layer's energy density.

    The first Piola-Kirchhoff stress of St Venant-Kirchhoff plus the volume penalty is
    ``P = F S + kappa (J - 1) cof F`` with ``S = 2 mu E + lam tr(E) I``, so

    ``dP_ij/dF_kl = d_ik S_lj + mu (F F^T)_ik d_jl + mu F_il F_kj + lam F_ij F_kl
    + kappa cof_ij cof_kl + kappa (J - 1) eps_ikn eps_jlq F_nq``.

    With ``psd`` it is the part that is positive semi-definite by construction, a Gauss-Newton
    tangent: ``S`` replaced by its positive part and the last term, indefinite whenever ``J != 1``,
    left out. Its quadratic form is then a sum of squares, ``tr(dF S+ dF^T) + 2 mu |sym(F^T dF)|^2
    + lam (F : dF)^2 + kappa (cof : dF)^2`` (``mu``, ``lam``, ``kappa`` >= 0). About 60 % of a moving
    lip's tetrahedra have indefinite Hessians. This part costs the eigenvalues of a 3 x 3 per tet
    (:func:`positive_part`: 1.2 ms for a 4,176-tet ``hard`` layer, against 4.1 ms by ``eigh``); clipping
    the negative eigenvalues of each tet's 12 x 12 Hessian (the solver's tangent until
    2026-12-06) cost a 12 x 12 one and took 10-17 % more line-search steps on ``hard`` motion.

    Parameters
    ----------
    F : (T, 3, 3) float
        Deformation gradients.
    mu, lam, kappa : (T,) float
        Lame parameters and volume penalty.
    psd : bool
        The positive semi-definite part instead of the exact derivative.
    """
    T = len(F)
    eye = np.eye(3)
    _, _, S, cof, J = strain_state(F, mu, lam)
    if psd:
        S = positive_part(S)
    C = np.einsum("ik,tlj->tijkl", eye, S)
    C += mu[:, None, None, None, None] * (np.einsum("tik,jl->tijkl", F @ np.swapaxes(F, -1, -2), eye)
                                          + np.einsum("til,tkj->tijkl", F, F))
    Fv, cv = F.reshape(T, 9), cof.reshape(T, 9)
    C = C.reshape(T, 9, 9)
    C += lam[:, None, None] * Fv[:, :, None] * Fv[:, None, :]
    C += kappa[:, None, None] * cv[:, :, None] * cv[:, None, :]
    if not psd:
        C += (kappa * (J - 1.0))[:, None, None] * (Fv @ _COFACTOR_DERIVATIVE).reshape(T, 9, 9)
    return C


def tet_hessians(x: np.ndarray, tets: np.ndarray, Dm_inv: np.ndarray, volume: np.ndarray, mu, lam, kappa,
                 psd: bool) -> np.ndarray:
    """(T, 12, 12) energy Hessian of each tet over its nodes' coordinates (node-major), or its
    positive semi-definite part (:func:`stress_derivative`).

    Parameters
    ----------
    x : (N, 3) float
        Node positions.
    tets : (T, 4) int
    Dm_inv : (T, 3, 3) float
        Inverse rest edge matrices (composed with any active strain).
    volume, mu, lam, kappa : (T,) float
    psd : bool
    """
    C = stress_derivative(deformation_gradients(x, tets, Dm_inv), mu, lam, kappa, psd=psd)
    gN = np.concatenate([-Dm_inv.sum(axis=1, keepdims=True), Dm_inv], axis=1)  # (T, 4, 3)
    G = np.zeros((len(tets), 9, 12))  # dF_ij (row-major) per node dof (a, k): delta_ik gN[a, j]
    for i in range(3):
        for a in range(4):
            G[:, 3 * i:3 * i + 3, 3 * a + i] = gN[:, a, :]
    K = volume[:, None, None] * np.swapaxes(G, 1, 2) @ C @ G
    return 0.5 * (K + np.swapaxes(K, 1, 2))


class StiffnessPattern:
    """Where each tet-Hessian entry, diagonal spring and contact spring lands in the data of a
    CSC stiffness over the dofs ``on``: built once, so each tangent is one ``bincount`` (a sparse
    COO-to-CSR conversion and a slice to the free dofs cost 5x more).

    Parameters
    ----------
    tets : (T, 4) int
    on : (3N,) bool
        The dofs the matrix keeps (all, or the free ones), in order.
    contact_pairs : (p, 2) int
        [upper, lower] node pairs whose y dofs a contact spring joins.
    """

    def __init__(self, tets: np.ndarray, on: np.ndarray, contact_pairs: np.ndarray):
        index = np.cumsum(on) - 1
        dof = (3 * tets[:, :, None] + np.arange(3)).reshape(len(tets), 12)
        up, lo = 3 * contact_pairs[:, 0] + 1, 3 * contact_pairs[:, 1] + 1
        rows = [np.broadcast_to(dof[:, :, None], (len(tets), 12, 12)).ravel(), np.arange(len(on)),
                np.stack([up, lo, up, lo], axis=1).ravel()]
        cols = [np.broadcast_to(dof[:, None, :], (len(tets), 12, 12)).ravel(), np.arange(len(on)),
                np.stack([up, lo, lo, up], axis=1).ravel()]
        kept = [on[r] & on[c] for r, c in zip(rows, cols, strict=True)]
        r = np.concatenate([r[k] for r, k in zip(rows, kept, strict=True)])
        c = np.concatenate([c[k] for c, k in zip(cols, kept, strict=True)])
        self.n = int(on.sum())
        cells, self.slot = np.unique(index[c] * self.n + index[r], return_inverse=True)  # column-major
        self.indices = cells % self.n
        self.indptr = np.searchsorted(cells // self.n, np.arange(self.n + 1))
        self.kept = [np.flatnonzero(k) for k in kept]

    def assemble(self, K: np.ndarray, diagonal: np.ndarray, contact: np.ndarray):
        """(n, n) CSC matrix: the tets' Hessians ``K`` (T, 12, 12), plus ``diagonal`` (3N,) on the
        diagonal and a spring of stiffness ``contact`` (p,) between each pair's y dofs."""
        from scipy.sparse import csc_matrix

        pair = np.stack([contact, contact, -contact, -contact], axis=1).ravel()
        values = np.concatenate([K.ravel()[self.kept[0]], diagonal[self.kept[1]], pair[self.kept[2]]])
        data = np.bincount(self.slot, values, len(self.indices))
        return csc_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))


def fill_reducing_order(A) -> np.ndarray:
    """(n,) int: the symmetric order in which SuperLU's minimum-degree ordering of ``A + A^T`` (a
    function of the sparsity pattern alone) eliminates ``A``'s unknowns, so that matrices of one
    pattern can be factorised in it without ordering each again (:func:`spd_solver`)."""
    from scipy.sparse.linalg import splu

    lu = splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    return np.argsort(lu.perm_c)


def spd_solver(A, order: np.ndarray | None = None):
    """``b -> A^-1 b`` for a sparse symmetric positive definite ``A``: SuperLU in its symmetric mode
    (a minimum-degree ordering of A + A^T and diagonal pivots), 2.5x faster than its general LU.

    ``order`` (:func:`fill_reducing_order` of a matrix with ``A``'s pattern) skips the ordering:
    ``A`` is permuted symmetrically and factorised in its natural order (the same elimination,
    17 against 21 ms for the 4,086 free dofs of a ``hard`` layer).
    """
    from scipy.sparse.linalg import splu

    options = {"diag_pivot_thresh": 0.0, "options": {"SymmetricMode": True}}
    if order is None:
        return splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A", **options).solve
    order = np.asarray(order)
    lu = splu(A.tocsr()[order][:, order].tocsc(), permc_spec="NATURAL", **options)

    def solve(b: np.ndarray) -> np.ndarray:
        x = np.empty_like(b, dtype=float)
        x[order] = lu.solve(b[order])
        return x

    return solve


def rest_stiffness(rest, tets, Dm_inv, volume, mu, lam, gum, pairs, kc):
    """(3N, 3N) linear-elastic stiffness of the tets at rest (Lamé ``lam``, ``mu``), plus springs."""
    from scipy.sparse import coo_matrix

    gN = np.concatenate([-Dm_inv.sum(axis=1, keepdims=True), Dm_inv], axis=1)  # (T, 4, 3) shape gradients
    # K[a, i, b, k] = V (lam dNa_i dNb_k + mu dNa_k dNb_i + mu delta_ik dNa . dNb)
    K = (lam[:, None, None, None, None] * np.einsum("tai,tbk->taibk", gN, gN)
         + mu[:, None, None, None, None] * np.einsum("tak,tbi->taibk", gN, gN)
         + mu[:, None, None, None, None] * np.einsum("taj,tbj,ik->taibk", gN, gN, np.eye(3)))
    K *= volume[:, None, None, None, None]
    dof = (3 * tets[:, :, None] + np.arange(3)).reshape(len(tets), 12)
    rows = np.broadcast_to(dof[:, :, None], (len(tets), 12, 12)).ravel()
    cols = np.broadcast_to(dof[:, None, :], (len(tets), 12, 12)).ravel()
    N3 = 3 * len(rest)
    M = coo_matrix((K.reshape(len(tets), 12, 12).ravel(), (rows, cols)), shape=(N3, N3)).tocsr()
    d = np.repeat(gum, 3).astype(float)
    if len(pairs):  # the contact springs as if engaged: a preconditioner only
        up, lo = 3 * pairs[:, 0] + 1, 3 * pairs[:, 1] + 1
        r = np.concatenate([up, lo, up, lo])
        c = np.concatenate([up, lo, lo, up])
        v = np.concatenate([np.full(len(up), kc), np.full(len(up), kc), np.full(len(up), -kc),
                            np.full(len(up), -kc)])
        M = M + coo_matrix((v, (r, c)), shape=(N3, N3)).tocsr()
    from scipy.sparse import diags

    return (M + diags(d)).tocsr()
