"""Bregler, Hertzmann & Biermann (1999): non-rigid shape by factorisation, as written.

1. Centre W (subtract each row's mean: eq 2's translation T).
2. Rank-3K SVD ``W = Q^ B^`` with the singular values split evenly (eq 6).
3. For every frame, reorder its two rows of Q^ into the K x 6 matrix q-bar (§3.2) and factor it
   by a rank-1 SVD into configuration weights l (K,) and pose R^ (2 x 3).
4. Metric upgrade (§3.3, footnote 1): one 3 x 3 G for the whole sequence, from linear least
   squares on ``L = G G^T``, so that every ``R^_f G`` has orthonormal rows; then
   ``R_f = R^_f G`` and ``S_i = G^-1 S^_i``.

Two ambiguities the paper leaves open are fixed here:

- **Per-frame scale.** (l, R^) is defined up to ``(a l, R^ / a)``. R^ is scaled to Frobenius
  norm sqrt(2) (two unit rows), and the metric constraints are written scale-free,
  ``r1 L r1^T - r2 L r2^T = 0`` and ``r1 L r2^T = 0`` per frame, with the single normalisation
  ``mean_f (r1 L r1^T + r2 L r2^T) = 2``. Footnote 1's "= 1" would force every frame's scale to
  one; the scale-free form is exact for scaled orthography. After the upgrade each frame's
  scale moves from R_f into l_f, and R_f is projected to the nearest orthonormal rows.
- **Per-frame sign.** The rank-1 factors are defined up to ``(-l, -R^)``. Every frame's sign is
  chosen so that its weights point the same way as the dominant weight direction of the
  sequence (the leading eigenvector of ``sum_f l_f l_f^T``), consistently across frames.

The result is exact for rigid data (K = 1, the Tomasi-Kanade case with per-frame scale). For
K > 1 the SVD factor is the true motion matrix times an unknown 3K x 3K transform, not a 3 x 3
one, so the rank-1 step does not see the true q-bar structure and the reconstruction is poor on
real sequences; that is the method as published.
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen.nrsfm._rotation import complete_rotations, nearest_orthonormal_rows
from lipgen.nrsfm._tracks import factor

__all__ = ["bregler_factorization"]

log = logging.getLogger(__name__)


def _quadratic_rows(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rows a with ``a . x = u L v^T`` for symmetric L = vech-like x (6,)."""
    return np.stack([u[:, 0] * v[:, 0], u[:, 1] * v[:, 1], u[:, 2] * v[:, 2],
                     u[:, 0] * v[:, 1] + u[:, 1] * v[:, 0],
                     u[:, 0] * v[:, 2] + u[:, 2] * v[:, 0],
                     u[:, 1] * v[:, 2] + u[:, 2] * v[:, 1]], axis=1)


def metric_upgrade(R_hat: np.ndarray) -> np.ndarray:
    """The 3 x 3 G of §3.3 from poses ``R_hat (F, 2, 3)``: least squares on L = G G^T.

    Raises
    ------
    ValueError
        If L has no positive part (the poses are degenerate).
    """
    r1, r2 = R_hat[:, 0], R_hat[:, 1]
    A = np.vstack([_quadratic_rows(r1, r1) - _quadratic_rows(r2, r2), _quadratic_rows(r1, r2)])
    n = (_quadratic_rows(r1, r1) + _quadratic_rows(r2, r2)).mean(0)
    # min |A x|^2 subject to n . x = 2 (Lagrange system)
    kkt = np.block([[2 * A.T @ A, n[:, None]], [n[None, :], np.zeros((1, 1))]])
    x = np.linalg.lstsq(kkt, np.r_[np.zeros(6), 2.0], rcond=None)[0][:6]
    L = np.array([[x[0], x[3], x[4]], [x[3], x[1], x[5]], [x[4], x[5], x[2]]])
    w, V = np.linalg.eigh(L)
    if w[-1] <= 0:
        raise ValueError(f"the metric upgrade found no positive definite G G^T (eigenvalues {w}); "
                         "the tracks show too little rotation")
    if w[0] <= 1e-9 * w[-1]:
        log.warning("metric upgrade: G G^T is not positive definite (eigenvalues %s); clipped", w)
    w = np.maximum(w, 1e-9 * w[-1])
    return V * np.sqrt(w)


def bregler_factorization(Wc: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Factor centred tracks into rotations, weights and basis shapes (Bregler et al. 1999).

    Parameters
    ----------
    Wc : (2F, P) float
        Centred tracks (each row has zero mean).
    k : int
        Number of basis shapes K.

    Returns
    -------
    R : (F, 3, 3) float
        Rotations (object to camera), third row the cross product of the first two.
    weights : (F, K) float
        Configuration weights l, including each frame's projection scale.
    basis : (K, 3, P) float
        Basis shapes S_i (object frame).
    """
    F = Wc.shape[0] // 2
    Q, B, _ = factor(Wc, 3 * k)
    q_bar = Q.reshape(F, 2, k, 3).transpose(0, 2, 1, 3).reshape(F, k, 6)
    U, s, Vt = np.linalg.svd(q_bar, full_matrices=False)
    weights = U[:, :, 0] * (s[:, :1] / np.sqrt(2.0))
    R_hat = Vt[:, 0, :] * np.sqrt(2.0)
    # One sign convention for the whole sequence (see module docstring).
    direction = np.linalg.eigh(weights.T @ weights)[1][:, -1]
    sign = np.sign(weights @ direction)
    sign[sign == 0] = 1.0
    weights = weights * sign[:, None]
    R_hat = (R_hat * sign[:, None]).reshape(F, 2, 3)
    G = metric_upgrade(R_hat)
    R2, scale = nearest_orthonormal_rows(R_hat @ G)
    weights = weights * scale[:, None]
    basis = np.linalg.solve(G, B.reshape(k, 3, -1))
    return complete_rotations(R2), weights, basis
