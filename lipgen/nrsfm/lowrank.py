"""Shapes of exactly K basis shapes given the rotations: variable projection with Levenberg-Marquardt.

With the rotations R_f fixed, the rank-K model ``W_f = Pi R_f sum_k c_fk B_k`` is linear in the
weights c_f of each frame once the basis B is fixed. Variable projection (Golub & Pereyra; for
matrix factorisation see Okatani & Deguchi 2007, Hong & Fitzgibbon 2015) eliminates the weights
and minimises the reprojection error over B alone,

    phi(B) = sum_f | w_f - A_f(B) c_f(B) |^2,   A_f(B) = [Pi R_f B_1, ..., Pi R_f B_K],

with Levenberg-Marquardt steps on Kaufman's Jacobian ``-(I - A_f A_f^+) G_f``. Alternating least
squares on (C, B) minimises the same cost but creeps along its valleys; variable projection
reaches the exact rank-K solution of noise-free data from the trace-norm start.

The normal equations (3KP unknowns) are solved matrix-free by preconditioned conjugate
gradients: a product with J^T J costs O(F P K), the per-point 3K x 3K blocks of ``G^T G``
serve as preconditioner.
"""

from __future__ import annotations

import logging

import numpy as np

__all__ = ["fit_rank_k_basis", "fit_rank_k"]

log = logging.getLogger(__name__)


def _frame_systems(R2, B, Wm, m):
    """Per frame, the linear unknowns given the basis: weights (K) and an image shift (2).

    Returns the design A (F, 2P, K + 2), its inverse normal matrices (F, K + 2, K + 2), the
    weights (F, K), the shifts (F, 2) and the residual (F, 2P).
    """
    F, P = m.shape
    K = B.shape[0]
    A = np.zeros((F, 2, P, K + 2))
    A[..., :K] = np.einsum("fij,kjp->fipk", R2, B) * m[:, None, :, None]
    A[:, 0, :, K] = m   # the shift: the translation taken from (completed) track means is only a
    A[:, 1, :, K + 1] = m   # start when points are missing
    A = A.reshape(F, 2 * P, K + 2)
    AtA = np.matmul(A.transpose(0, 2, 1), A)
    reg = 1e-13 * np.trace(AtA, axis1=1, axis2=2)[:, None, None] + 1e-300
    Minv = np.linalg.inv(AtA + reg * np.eye(K + 2))
    x = np.matmul(Minv, np.matmul(A.transpose(0, 2, 1), Wm[..., None]))[..., 0]
    res = Wm - np.matmul(A, x[..., None])[..., 0]
    return A, Minv, x[:, :K], x[:, K:], res


def _operators(R2, m, A, Minv, C):
    """Kaufman's Jacobian as G (basis step -> image change), its transpose Gt, and the projector
    ``I - A_f A_f^+`` that removes what the weights can absorb."""
    F, P = m.shape
    AM = np.matmul(A, Minv)

    def G(v):  # (K, 3, P) -> (F, 2P)
        return (np.einsum("fij,fk,kjp->fip", R2, C, v, optimize=True) * m[:, None, :]).reshape(F, -1)

    def Gt(u):  # (F, 2P) -> (K, 3, P)
        back = np.matmul(R2.transpose(0, 2, 1), u.reshape(F, 2, P) * m[:, None, :])
        return np.einsum("fk,fjp->kjp", C, back, optimize=True)

    def proj(u):  # (F, 2P)
        return u - np.einsum("fnk,fk->fn", AM, np.einsum("fnk,fn->fk", A, u))

    return G, Gt, proj


def _pcg(ops, damp, Vinv, g, max_iter: int, rtol: float):
    """Conjugate gradients for ``(J^T J + diag(damp)) x = g`` (x, g, damp (K, 3, P)), J from
    ``ops = (G, Gt, proj)``, preconditioned by per-point blocks ``Vinv`` (P, 3K, 3K); stops early
    on a non-positive curvature (gauge directions)."""
    K, _, P = g.shape
    G, Gt, proj = ops

    def op(v):
        return Gt(proj(G(v))) + damp * v

    def prec(r):
        return np.matmul(Vinv, r.transpose(2, 0, 1).reshape(P, 3 * K, 1)).reshape(P, K, 3).transpose(1, 2, 0)

    x = np.zeros_like(g)
    r = g.copy()
    z = prec(r)
    p = z.copy()
    rz = float((r * z).sum())
    g2 = float((g * g).sum())
    for _ in range(max_iter):
        q = op(p)
        pq = float((p * q).sum())
        if not (pq > 0 and np.isfinite(pq)):
            break
        alpha = rz / pq
        x += alpha * p
        r -= alpha * q
        if float((r * r).sum()) <= rtol**2 * g2:
            break
        z = prec(r)
        rz_new = float((r * z).sum())
        p = z + (rz_new / rz) * p
        rz = rz_new
    return x

def fit_rank_k_basis(Wc: np.ndarray, R: np.ndarray, B0: np.ndarray, mask: np.ndarray | None = None,
                     max_iter: int = 50, tol: float = 1e-10, gain_tol: float = 1e-3, cg_iter: int = 20,
                     cg_tol: float = 1e-2):
    """Basis shapes and weights minimising the reprojection error with the rotations fixed.

    Parameters
    ----------
    Wc : (2F, P) float
        Tracks with each frame's translation removed (unobserved entries ignored).
    R : (F, 3, 3) float
        Rotations, object to camera (fixed).
    B0 : (K, 3, P) float
        Starting basis (e.g. the rank-K cut of the trace-norm shapes).
    mask : (F, P) bool, optional
        Observed points.
    max_iter : int
        Cap on Levenberg-Marquardt iterations.
    tol : float
        Stop when the cost falls below ``tol**2`` of its start.
    gain_tol : float
        Stop when an accepted step lowers the cost by less than this fraction (on noisy tracks
        the last steps barely move the shapes; on exact ones steps keep gaining until the end).
    cg_iter : int
        Cap on conjugate-gradient iterations per step (an inexact Newton step is enough far from
        the solution and costs a fraction of an exact one).
    cg_tol : float
        Conjugate gradients stop when the residual falls below this fraction of the right side.

    Returns
    -------
    weights : (F, K) float
    basis : (K, 3, P) float
        Orthonormal as 3P-vectors.
    shift : (F, 2) float
        Image shift of each frame to add to the translation removed from ``Wc``.
    history : list of float
        Cost (half the sum of squared residuals) after each accepted step, the start first.
    """
    F, P = R.shape[0], Wc.shape[1]
    K = B0.shape[0]
    m = np.ones((F, P)) if mask is None else mask.astype(float)
    R2 = R[:, :2]
    Wm = np.where(m[:, None, :] > 0, Wc.reshape(F, 2, P), 0.0).reshape(F, 2 * P)
    Pi = np.matmul(R2.transpose(0, 2, 1), R2)                  # (F, 3, 3) in-image projector

    def orthonormal(B):
        q = np.linalg.qr(B.reshape(K, -1).T)[0]
        return q.T.reshape(K, 3, P)

    B = orthonormal(B0)
    A, Minv, C, shift, res = _frame_systems(R2, B, Wm, m)
    cost = 0.5 * float((res**2).sum())
    history = [cost]
    lam = 1e-3
    n = 3 * K
    for _ in range(max_iter):
        if cost <= tol**2 * history[0]:
            break
        G, Gt, proj = _operators(R2, m, A, Minv, C)
        g = Gt(res)                                           # minus the gradient
        # block-Jacobi preconditioner: per point sum_f m (c c^T) (x) Pi_f, (P, 3K, 3K)
        CC = C[:, :, None] * C[:, None, :]
        kron = (CC[:, :, None, :, None] * Pi[:, None, :, None, :]).reshape(F, n * n)
        V = (m.T @ kron).reshape(P, n, n)
        diag = np.einsum("pii->pi", V)
        damp = np.maximum(diag, 1e-12 * diag.max())
        accepted = False
        while not accepted and lam < 1e10:
            x = _pcg((G, Gt, proj), (lam * damp).reshape(P, K, 3).transpose(1, 2, 0),
                     np.linalg.inv(V + lam * damp[:, :, None] * np.eye(n)), g, cg_iter, cg_tol)
            Bn = orthonormal(B + x)
            An, Mn, Cn, shiftn, resn = _frame_systems(R2, Bn, Wm, m)
            new = 0.5 * float((resn**2).sum())
            if new < cost:
                accepted = True
                gain = (cost - new) / cost
                B, A, Minv, C, shift, res, cost = Bn, An, Mn, Cn, shiftn, resn, new
                lam = max(lam / 5, 1e-9)
            else:
                lam *= 5
        history.append(cost)
        if not accepted or gain < gain_tol:
            break
    log.debug("rank-K basis (variable projection): %d steps, cost %.3e -> %.3e", len(history) - 1,
              history[0], cost)
    return C, B, shift, history


EXACT_RTOL = 1e-10
"""A fit is exact when its cost is below this fraction of the cost of the zero model."""


def fit_rank_k(Wc: np.ndarray, R: np.ndarray, B0: np.ndarray, mask: np.ndarray | None = None, *,
               exact_model: bool = False, n_starts: int = 8, seed: int = 0, max_iter: int = 50):
    """Rank-K basis by variable projection from ``B0``, with random restarts when the data are exact.

    The cost has local minima; in general there is no telling whether a fit is the global one.
    When the tracks are exactly of rank <= 3K (``exact_model``: noise-free data of K basis shapes,
    possibly degenerate) the global minimum is an exact fit, so a start that ends above
    :data:`EXACT_RTOL` is known to be stuck: seeded random bases are then tried, up to
    ``n_starts``, until one fits exactly; the lowest cost wins. Otherwise only ``B0`` is refined.

    Parameters
    ----------
    Wc : (2F, P) float
    R : (F, 3, 3) float
    B0 : (K, 3, P) float
    mask : (F, P) bool, optional
    exact_model : bool
        The tracks have numerical rank <= 3K.
    n_starts : int
        Random restarts allowed when ``exact_model`` and the start from B0 is not exact.
    seed : int
    max_iter : int
        Levenberg-Marquardt cap per start.

    Returns
    -------
    weights : (F, K) float
    basis : (K, 3, P) float
    shift : (F, 2) float
        See :func:`fit_rank_k_basis`.
    info : dict
        ``shape_cost`` (relative to the zero model: first start, final), ``shape_starts`` used,
        ``shape_exact``.
    """
    F, P = R.shape[0], Wc.shape[1]
    seen = np.ones((F, P), dtype=bool) if mask is None else mask
    zero = 0.5 * float((np.where(seen[:, None, :], Wc.reshape(F, 2, P), 0.0) ** 2).sum())
    C, B, shift, hist = fit_rank_k_basis(Wc, R, B0, mask, max_iter=max_iter)
    first = hist[-1] / zero
    best = (hist[-1], C, B, shift)
    used = 1
    if exact_model and best[0] > EXACT_RTOL * zero:
        rng = np.random.default_rng(seed)
        for _ in range(n_starts):
            C, B, shift, hist = fit_rank_k_basis(Wc, R, rng.standard_normal(B0.shape), mask,
                                                 max_iter=max_iter)
            used += 1
            if hist[-1] < best[0]:
                best = (hist[-1], C, B, shift)
            if best[0] <= EXACT_RTOL * zero:
                break
        log.info("rank-K shapes: start from the trace-norm cut stuck at %.2e of the track energy; %d "
                 "random restarts, best %.2e", first, used - 1, best[0] / zero)
    cost, C, B, shift = best
    return C, B, shift, {"shape_cost": [first, cost / zero], "shape_starts": used,
                  "shape_exact": bool(cost <= EXACT_RTOL * zero)}
