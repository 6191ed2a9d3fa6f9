"""The stiffness of the truth subject's tissue layer (:mod:`lipgen.subject.layer`).

Each tetrahedron's energy Hessian over its 12 node coordinates is the stress derivative ``dP/dF``
(:func:`stress_derivative`), exact or its positive semi-definite part, contracted with the shape
gradients in closed form (:func:`tet_hessians`, tets along the last axis), and summed into a sparse
matrix whose pattern is built once (:class:`StiffnessPattern`). :class:`PatternCholesky` factorises
matrices of that pattern, analysed once; :func:`rest_stiffness` is linear elasticity at rest (the
solver's first preconditioner, and the small-strain theory the tests use).
"""

from __future__ import annotations

import numpy as np

from lipgen.fem import solver as fem_solver  # its cholmod_available is looked up per call (tests patch it)

__all__ = ["deformation_gradients", "green_strain_stress", "cofactors", "determinant", "strain_state",
           "symmetric_eigenvalues",
           "positive_part", "stress_derivative", "tet_hessians", "StiffnessPattern", "PatternCholesky",
           "spd_solver", "rest_stiffness"]

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
    ``J = det F`` (T,) of deformation gradients ``F`` (T, 3, 3): :func:`green_strain_stress`,
    :func:`cofactors` and :func:`determinant` with the tets first."""
    F_last = np.ascontiguousarray(np.moveaxis(F, 0, -1))
    E, trE, S = green_strain_stress(F_last, mu, lam)
    cof = cofactors(F_last)
    return (np.moveaxis(E, -1, 0), trE, np.moveaxis(S, -1, 0), np.moveaxis(cof, -1, 0),
            determinant(F_last, cof))


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


def tet_hessians(F: np.ndarray, gN: np.ndarray, volume: np.ndarray, mu, lam, kappa, psd: bool) -> np.ndarray:
    """(12, 12, T) energy Hessian of each tet over its nodes' coordinates (node-major), or its
    positive semi-definite part (:func:`stress_derivative`'s ``psd``), tets last.

    :func:`stress_derivative`'s terms contracted with the shape gradients in closed form, with
    ``q_a = F g_a``, ``r_a = cof(F) g_a`` and ``g_a`` node ``a``'s shape gradient: entry
    ``[(a, m), (b, n)]`` is ``V (d_mn g_a.S g_b + mu (F F^T)_mn g_a.g_b + mu q_bm q_an + lam q_am q_bn
    + kappa r_am r_bn + kappa (J - 1) eps_mnp (F (g_a x g_b))_p)``, the last term only without
    ``psd``. The tets lie along the last axis so that every product runs over contiguous memory
    (5-6.5 against 12-15 ms for :func:`stress_derivative` chained with the shape gradients, 4,176 tets).

    Parameters
    ----------
    F : (3, 3, T) float
        Deformation gradients, tets last.
    gN : (4, 3, T) float
        Shape gradients ``g_a`` of each tet's nodes, tets last.
    volume, mu, lam, kappa : (T,) float
    psd : bool
    """
    T = F.shape[-1]
    vol_mu, vol_lam, vol_kappa = volume * mu, volume * lam, volume * kappa
    _, _, S = green_strain_stress(F, mu, lam)
    if psd:
        S = np.ascontiguousarray(positive_part(np.ascontiguousarray(S.transpose(2, 0, 1))).transpose(1, 2, 0))
    cof = cofactors(F)
    q = np.einsum("mjt,ajt->amt", F, gN)
    r = np.einsum("mjt,ajt->amt", cof, gN)
    H = np.einsum("ajt,jlt,blt->abt", gN, volume * S, gN)
    D = np.einsum("ajt,bjt->abt", gN, gN) * vol_mu
    B = np.einsum("mjt,njt->mnt", F, F)
    K = D[:, None, :, None] * B[None, :, None, :]
    K += (vol_mu * q).transpose(1, 0, 2)[None, :, :, None] * q[:, None, None]   # mu q_bm q_an
    K += (vol_lam * q)[:, :, None, None] * q[None, None]
    K += (vol_kappa * r)[:, :, None, None] * r[None, None]
    for m in range(3):
        K[:, m, :, m] += H
    if not psd:
        w = np.cross(gN[:, None], gN[None, :], axis=2)                     # (4, 4, 3, T): g_a x g_b
        z = np.einsum("pqt,abqt->abpt", F, w) * (vol_kappa * (determinant(F, cof) - 1.0))
        for m, n, p in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
            K[:, m, :, n] += z[:, :, p]
            K[:, n, :, m] -= z[:, :, p]
    return K.reshape(12, 12, T)


def green_strain_stress(F: np.ndarray, mu, lam):
    """The Green strain ``E`` (3, 3, T), its trace (T,) and the St Venant-Kirchhoff second
    Piola-Kirchhoff stress ``S = 2 mu E + lam tr(E) I`` (3, 3, T) of ``F`` (3, 3, T), tets last
    (:func:`strain_state` gives the same with the tets first)."""
    E = 0.5 * np.einsum("kat,kbt->abt", F, F)
    for i in range(3):
        E[i, i] -= 0.5
    trE = E[0, 0] + E[1, 1] + E[2, 2]
    S = (2.0 * mu) * E
    for i in range(3):
        S[i, i] += lam * trE
    return E, trE, S


def cofactors(F: np.ndarray) -> np.ndarray:
    """(3, 3, T) cofactor matrices ``det(F) F^-T`` of ``F`` (3, 3, T): column ``c`` is the cross
    product of F's other two columns."""
    cof = np.empty_like(F)
    f = F[:, 0], F[:, 1], F[:, 2]
    for c, (u, v) in enumerate(((f[1], f[2]), (f[2], f[0]), (f[0], f[1]))):
        cof[0, c] = u[1] * v[2] - u[2] * v[1]
        cof[1, c] = u[2] * v[0] - u[0] * v[2]
        cof[2, c] = u[0] * v[1] - u[1] * v[0]
    return cof


def determinant(F: np.ndarray, cof: np.ndarray) -> np.ndarray:
    """(T,) ``det F`` from ``F`` and its cofactors (3, 3, T)."""
    return F[0, 0] * cof[0, 0] + F[1, 0] * cof[1, 0] + F[2, 0] * cof[2, 0]


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
        shape = (12, 12, len(tets))   # tet_hessians' layout: tets last
        rows = [np.broadcast_to(dof.T[:, None, :], shape).ravel(), np.arange(len(on)),
                np.stack([up, lo, up, lo], axis=1).ravel()]
        cols = [np.broadcast_to(dof.T[None, :, :], shape).ravel(), np.arange(len(on)),
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
        """(n, n) CSC matrix: the tets' Hessians ``K`` (12, 12, T) (:func:`tet_hessians`), plus
        ``diagonal`` (3N,) on the diagonal and a spring of stiffness ``contact`` (p,) between each
        pair's y dofs."""
        from scipy.sparse import csc_matrix

        pair = np.stack([contact, contact, -contact, -contact], axis=1).ravel()
        values = np.concatenate([K.ravel()[self.kept[0]], diagonal[self.kept[1]], pair[self.kept[2]]])
        data = np.bincount(self.slot, values, len(self.indices))
        return csc_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))


class PatternCholesky:
    """Factorisations of sparse symmetric positive definite matrices that share one sparsity
    pattern (the layer's tangents): the fill-reducing analysis is done once, each
    :meth:`factor` redoes only the numbers.

    ``method`` ``"auto"`` takes SuiteSparse CHOLMOD through cvxopt when it imports (supernodal
    Cholesky, the analysis reused: 4.4 ms a factorisation and 0.26 ms a solve for the 4,086 free
    dofs of a ``hard`` layer), else SuperLU in symmetric mode in a stored minimum-degree order
    (17-23 ms and 0.5-1 ms); see :mod:`lipgen.fem.solver` for why cvxopt stays optional.

    Parameters
    ----------
    A : (n, n) sparse
        A matrix of the pattern (its values are not factorised).
    method : {"auto", "cholmod", "superlu"}
    """

    METHODS = ("auto", "cholmod", "superlu")

    def __init__(self, A, method: str = "auto"):
        if method not in self.METHODS:
            raise ValueError(f"method must be one of {self.METHODS}, got {method!r}")
        available = fem_solver.cholmod_available()
        self.method = ("cholmod" if available else "superlu") if method == "auto" else method
        if self.method == "cholmod" and not available:
            raise ImportError("method 'cholmod' needs cvxopt: pip install 'lipgen[fast]' (or method 'auto')")
        A = A.tocsc()
        A.sort_indices()
        self.shape, self.nnz = A.shape, A.nnz
        self.indptr, self.indices = A.indptr.copy(), A.indices.copy()
        if self.method == "cholmod":
            import cvxopt
            from cvxopt import cholmod

            cols = np.repeat(np.arange(A.shape[1]), np.diff(A.indptr))
            self._lower = A.indices >= cols
            self._M = cvxopt.spmatrix(cvxopt.matrix(A.data[self._lower]),
                                      cvxopt.matrix(A.indices[self._lower].astype(np.int64)),
                                      cvxopt.matrix(cols[self._lower].astype(np.int64)), A.shape)
            with fem_solver.cholmod_supernodal():
                self._symbolic = cholmod.symbolic(self._M, uplo="L")
        else:
            from scipy.sparse.linalg import splu

            lu = splu(A, permc_spec="MMD_AT_PLUS_A", **_SUPERLU_SPD)
            self._order = np.argsort(lu.perm_c)

    def factor(self, A):
        """``b -> A^-1 b`` (b: (n,) float) for ``A`` of the stored pattern. With CHOLMOD the
        factor is overwritten in place: a solver is valid until the next call.

        Raises
        ------
        numpy.linalg.LinAlgError
            ``A`` is not positive definite (a non-positive pivot).
        ValueError
            ``A`` does not have the stored pattern.
        """
        A = A.tocsc()
        A.sort_indices()
        if A.shape != self.shape or A.nnz != self.nnz or not (np.array_equal(A.indptr, self.indptr)
                                                                and np.array_equal(A.indices, self.indices)):
            raise ValueError(f"the matrix ({A.shape}, {A.nnz} entries) does not have the analysed pattern "
                             f"({self.shape}, {self.nnz} entries)")
        if self.method == "cholmod":
            return self._factor_cholmod(A)
        return self._factor_superlu(A)

    def _factor_cholmod(self, A):
        import cvxopt
        from cvxopt import cholmod

        self._M.V = cvxopt.matrix(A.data[self._lower])
        with fem_solver.cholmod_supernodal():
            try:
                cholmod.numeric(self._M, self._symbolic)
            except ArithmeticError as exc:
                raise np.linalg.LinAlgError(f"the {self.shape[0]}-dof matrix is not positive definite "
                                            f"(CHOLMOD: non-positive pivot {exc})") from None
        symbolic = self._symbolic

        def solve(b: np.ndarray) -> np.ndarray:
            x = cvxopt.matrix(np.asarray(b, float))
            cholmod.solve(symbolic, x)
            return np.asarray(x).ravel()

        return solve

    def _factor_superlu(self, A):
        from scipy.sparse.linalg import splu

        order = self._order
        lu = splu(A.tocsr()[order][:, order].tocsc(), permc_spec="NATURAL", **_SUPERLU_SPD)
        pivots = lu.U.diagonal()
        if not (pivots > 0).all():
            raise np.linalg.LinAlgError(f"the {self.shape[0]}-dof matrix is not positive definite "
                                        f"(SuperLU: pivot {pivots.min():.3g})")

        def solve(b: np.ndarray) -> np.ndarray:
            x = np.empty(len(order))
            x[order] = lu.solve(np.asarray(b, float)[order])
            return x

        return solve


_SUPERLU_SPD = {"diag_pivot_thresh": 0.0, "options": {"SymmetricMode": True}}
"""SuperLU for a symmetric positive definite matrix: diagonal pivots, a symmetric order (2.5x
faster than its general LU)."""


def spd_solver(A):
    """``b -> A^-1 b`` for one sparse symmetric positive definite ``A`` (SuperLU, symmetric mode)."""
    from scipy.sparse.linalg import splu

    return splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A", **_SUPERLU_SPD).solve


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
