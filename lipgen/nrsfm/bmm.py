"""Shapes given rotations: Dai, Li & He's block matrix method (minimum trace norm).

With the rotations known, every frame's object-frame shape is fixed by its image except for
one depth per point: ``S_f = R2_f^T W_f + r3_f z_f^T``. Among all such shape sequences the
block matrix method takes the one whose F x 3P shape matrix ``S#`` has the least trace
(nuclear) norm, the convex surrogate of "fewest basis shapes":

    minimise ||S#||_*  subject to  Pi R_f S_f = W_f  at every observed point.

Unobserved points are free. Solved by the inexact augmented Lagrangian method (ADMM with a
penalty growing geometrically). Then ``S#`` is cut to rank K by SVD.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.linalg

__all__ = ["min_trace_norm_shapes", "rank_k_shapes"]

log = logging.getLogger(__name__)


_FEW = 12
"""While the last shrinkage kept at most this many values (the rank climbs slowly, from 0), the next
asks LAPACK's ``dsyevr`` for the eigenpairs above the threshold only: on drink's 123 x 123 Gram matrix
0.36-0.8 ms for 1-10 of them against 1.0 ms for all (``dsyevd``), and slower from ~15 on."""


def min_trace_norm_shapes(Wc: np.ndarray, R: np.ndarray, mask: np.ndarray | None = None,
                          tol: float = 1e-8, max_iter: int = 1000, growth: float = 1.1) -> np.ndarray:
    """Object-frame shapes of least trace norm that reproject exactly onto the tracks.

    Parameters
    ----------
    Wc : (2F, P) float
        Tracks with each frame's translation removed (unobserved entries ignored).
    R : (F, 3, 3) float
        Rotations, object to camera.
    mask : (F, P) bool, optional
        Observed points (all by default).
    tol : float
        Stop when the constraint violation is below ``tol`` times the norm of the shapes.
    max_iter : int
        Iteration cap.
    growth : float
        Factor by which the augmented-Lagrangian penalty grows per iteration.

    Returns
    -------
    (F, 3, P) float
        Shapes S_f in the object frame.
    """
    F, P = R.shape[0], Wc.shape[1]
    Wf = Wc.reshape(F, 2, P)
    seen = np.ones((F, P), dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    if seen.shape != (F, P):
        raise ValueError(f"mask must be (F, P) = {(F, P)} bool, got shape {seen.shape}")
    seen3 = seen[:, None, :]
    base = np.einsum("fji,fjp->fip", R[:, :2], Wf) * seen3   # R2^T W: in-image part, object frame
    depth_axis = R[:, 2][:, :, None]                           # r3_f as (F, 3, 1)
    A = base.copy()
    Y = np.zeros_like(A)
    rho = 1.0 / max(np.linalg.norm(base.reshape(F, -1), 2), 1e-300)
    norm0 = np.linalg.norm(base)
    it = 0
    complete = bool(seen.all())
    # the plain iteration's elementwise arithmetic (the same bits) in buffers made once; the
    # shrinkage's cheaper routes give its values to rounding
    Y_rho, Z, X = np.empty_like(A), np.empty_like(A), np.empty_like(A)
    rank = 0
    for it in range(1, max_iter + 1):  # noqa: B007 (count reported after the loop)
        np.divide(Y, rho, out=Y_rho)
        rank = _shrink(np.subtract(A, Y_rho, out=Z).reshape(F, -1), 1.0 / rho, out=X.reshape(F, -1),
                       few=rank <= _FEW)
        T = np.add(X, Y_rho, out=Y_rho)                        # X + Y / rho
        depth = np.einsum("fik,fip->fkp", depth_axis, T)      # (F, 1, P)
        np.multiply(depth_axis, depth, out=A)
        A += base
        if not complete:
            np.copyto(A, T, where=~seen3)
        X -= A                                                 # X - A from here on
        gap = np.linalg.norm(X)
        X *= rho
        Y += X
        if gap <= tol * max(np.linalg.norm(A), norm0):
            break
        rho *= growth
    else:
        log.warning("trace-norm shapes stopped after %d iterations (constraint gap %.2e of the shape "
                    "norm)", max_iter, gap / max(np.linalg.norm(A), 1e-300))
    log.debug("trace-norm shapes: %d iterations, rank %d", it, rank)
    return A


def _shrink(Z: np.ndarray, tau: float, out: np.ndarray, few: bool = False) -> int:
    """Singular value soft-thresholding of a tall matrix, through the eigenvectors of its Gram matrix,
    written into ``out`` (the shape of Z); returns the rank kept.

    ``Z V diag(max(1 - tau / s, 0)) V^T`` equals ``U diag(max(s - tau, 0)) V^T`` for ``Z = U s V^T``;
    the n x n Gram matrix (n = 3P columns) is far cheaper to decompose than Z itself. With k of the n
    values kept, ``(Z Vk) (w Vk^T)`` costs 2 F n k multiply-adds and ``Z (Vk w Vk^T)`` F n^2 + n^2 k: the
    cheaper of the two (the rank climbs to ~n as the penalty grows: on drink 120 of 123 for the last
    third of the iterations, where the one product takes 0.9 ms against 2.3 ms). ``few``: only the
    eigenpairs above ``tau^2`` are computed (:data:`_FEW`); the same values to rounding.
    """
    G = Z.T @ Z
    if not np.isfinite(G).all():  # dsyevr would return no eigenpairs, i.e. a silent zero
        raise np.linalg.LinAlgError("trace-norm shrinkage: the shapes hold NaN or inf")
    if few and tau * tau < np.inf:   # dsyevr needs finite bounds
        w, V = scipy.linalg.eigh(G, subset_by_value=(tau * tau, np.inf), driver="evr", check_finite=False)
    else:
        w, V = np.linalg.eigh(G)
    s = np.sqrt(np.maximum(w, 0.0))
    keep = s > tau
    if not keep.any():
        out[...] = 0.0
        return 0
    Vk = V[:, keep]
    factor = 1.0 - tau / s[keep]
    F, n = Z.shape
    k = Vk.shape[1]
    if F * n + n * k < 2 * F * k:
        np.matmul(Z, (Vk * factor) @ Vk.T, out=out)
    else:
        np.matmul((Z @ Vk) * factor, Vk.T, out=out)
    return k


def rank_k_shapes(shapes: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Best rank-K approximation of a shape sequence, as weights and centred basis shapes.

    Parameters
    ----------
    shapes : (F, 3, P) float
    k : int

    Returns
    -------
    weights : (F, K) float
    basis : (K, 3, P) float
        Orthonormal (as 3P-vectors) and centred (each coordinate row has zero mean over points).
    """
    F, _, P = shapes.shape
    centred = shapes - shapes.mean(axis=2, keepdims=True)
    U, s, Vt = np.linalg.svd(centred.reshape(F, -1), full_matrices=False)
    return U[:, :k] * s[:k], Vt[:k].reshape(k, 3, P)
