"""Camera rotations: orthonormal-row projections and the corrective triple of Dai, Li & He (2012).

Under (scaled) orthography the rank-3K factor ``M`` (2F x 3K) of the centred tracks equals the
true motion matrix times an unknown invertible 3K x 3K corrective transform. Any one column
triple ``g`` (3K x 3) of that transform gives ``M_f g = c_f R_f`` for every frame f: a scaled
2 x 3 matrix with orthonormal rows. Dai, Li & He recover ``Q = g g^T`` from these two linear
constraints per frame (trace-norm relaxation, then nonlinear refinement of g); any rank-3 psd
solution gives the rotations. Here g is found directly by Levenberg-Marquardt on the same
constraints from several starts.
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen._rotation import rotation_matrix as expm_so3
from lipgen._rotation import skew

from ._lm import levenberg_marquardt

__all__ = ["complete_rotations", "nearest_orthonormal_rows", "expm_so3", "skew",
           "corrective_triple", "rotations_from_triple", "orient_frames"]

log = logging.getLogger(__name__)


def complete_rotations(R2: np.ndarray) -> np.ndarray:
    """Full rotations ``(F, 3, 3)`` from orthonormal row pairs ``(F, 2, 3)``: third row r1 x r2."""
    return np.concatenate([R2, np.cross(R2[:, 0], R2[:, 1])[:, None, :]], axis=1)


def nearest_orthonormal_rows(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest matrices with orthonormal rows, and the scales, of ``A (F, 2, 3)``.

    ``A_f ~ scale_f * R_f`` with ``R_f R_f^T = I``; R_f is the polar factor and scale_f the mean
    singular value (the least-squares scale).
    """
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    return U @ Vt, s.mean(axis=1)


def _metric_terms(g: np.ndarray, M1: np.ndarray, M2: np.ndarray):
    p, q = M1 @ g, M2 @ g
    return p, q, (p * p).sum(1), (q * q).sum(1), (p * q).sum(1)


class _Metric:
    """The corrective triple's residuals and Jacobian on one motion factor (rows M1, M2 of each frame).

    The residual's arithmetic is that of the plain formulas, element for element (the same bits); the
    Jacobian's is regrouped (the same values to rounding; see ``tests/test_nrsfm_rotation_lm.py``).
    Less work per call: M's columns repeated once per factor instead of per Jacobian, the terms of
    the last residual's x reused by the Jacobian at that x (Levenberg-Marquardt asks for both), and
    no temporaries stacked.
    """

    def __init__(self, M1: np.ndarray, M2: np.ndarray):
        self.M1, self.M2 = M1, M2
        # da[f, 3i + j] = 2 M1[f, i] p[f, j]: one product of a repeated M1 and a tiled p (numpy's
        # broadcast over a last axis of 3 took most of the Jacobian's time)
        self.M1r, self.M2r = np.repeat(M1, 3, axis=1), np.repeat(M2, 3, axis=1)
        self._last = None

    def _terms(self, x: np.ndarray):
        key = np.ascontiguousarray(x, dtype=np.float64).tobytes()   # the same bits, not only equal values
        if self._last is not None and self._last[0] == key:
            return self._last[1]
        terms = _metric_terms(x.reshape(-1, 3), self.M1, self.M2)
        self._last = (key, terms)
        return terms

    def residual(self, x: np.ndarray) -> np.ndarray:
        """(2F,) residuals ``|m1 g|^2 - |m2 g|^2`` and ``2 (m1 g).(m2 g)`` over their mean scale."""
        p, q, a, b, c = self._terms(x)
        scale = np.mean(a + b)
        return np.concatenate([a - b, 2 * c]) / scale

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """(2F, 3r) Jacobian of :meth:`residual` at x.

        Row f of the residual ``a - b`` over ``scale`` has the derivative ``2 (m1 (x) p - m2 (x) q) / scale
        - r1 dscale / scale``, with ``dscale`` the mean over frames of ``2 (m1 (x) p + m2 (x) q)``, that
        is ``2 (M1^T p + M2^T q) / F`` (one small matrix product instead of a pass over the F x 3r
        terms); likewise ``2 c``. The factors ``2 / scale`` go into the F x 3 p and q before they are
        tiled, so each half of J costs four passes over F x 3r.
        """
        p, q, a, b, c = self._terms(x)
        F, r = self.M1.shape
        scale = np.mean(a + b)
        w = 2.0 / scale
        pt, qt = np.tile(p * w, (1, r)), np.tile(q * w, (1, r))
        dscale = (self.M1.T @ p + self.M2.T @ q).ravel() * (w / F)   # d scale / dx over scale
        r1, r2 = (a - b) / scale, 2 * c / scale
        J = np.empty((2 * F, 3 * r))
        J1, J2 = J[:F], J[F:]
        tmp = np.empty((F, 3 * r))
        np.multiply(self.M1r, pt, out=J1)                  # w m1 (x) p - w m2 (x) q - r1 dscale
        J1 -= np.multiply(self.M2r, qt, out=tmp)
        J1 -= np.multiply(r1[:, None], dscale, out=tmp)
        np.multiply(self.M1r, qt, out=J2)                  # w (m1 (x) q + m2 (x) p) - r2 dscale
        J2 += np.multiply(self.M2r, pt, out=tmp)
        J2 -= np.multiply(r2[:, None], dscale, out=tmp)
        return J


def corrective_triple(M: np.ndarray, n_starts: int = 4, seed: int = 0,
                      max_iter: int = 300) -> tuple[np.ndarray, float]:
    """One column triple g of the corrective transform, from the orthonormality of ``M_f g``.

    Minimises, over g (r x 3), the scale-free residuals ``|m1 g|^2 - |m2 g|^2`` and
    ``2 (m1 g).(m2 g)`` of every frame (rows m1, m2 of M_f), divided by the mean of
    ``|m1 g|^2 + |m2 g|^2``. The first start is the leading triple (the rigid, Tomasi-Kanade
    guess); the others are seeded random triples. The lowest cost wins; the search stops early
    once two starts have reached the same lowest cost (to 1e-6), or a cost of zero. A later start
    stops once it reaches the best cost (to 1e-6), or once it settles where it cannot beat it
    (:func:`._lm.levenberg_marquardt`'s ``match`` and ``beat``).

    Parameters
    ----------
    M : (2F, r) float
        Motion factor of the centred tracks (r >= 3).
    n_starts : int
        Number of starting points.
    seed : int
        Seed of the random starts.
    max_iter : int
        Levenberg-Marquardt iterations per start (:func:`._lm.levenberg_marquardt`).

    Returns
    -------
    g : (r, 3) float
    cost : float
        Half the sum of squared scale-free residuals at g (0 for exact data).
    """
    r = M.shape[1]
    metric = _Metric(M[0::2], M[1::2])
    rng = np.random.default_rng(seed)
    starts = [np.eye(r, 3)] + [rng.standard_normal((r, 3)) for _ in range(max(n_starts, 1) - 1)]
    best, confirmed = None, False
    for g0 in starts:
        # a later start that reaches the best cost to within `same` confirms it
        same = None if best is None else 1e-6 * max(best[1], 1e-300)
        x, cost, _ = levenberg_marquardt(metric.residual, metric.jacobian, g0.ravel(),
                                         max_iter=max_iter, beat=None if best is None else best[1],
                                         match=None if best is None else (best[1] - same, best[1] + same))
        if best is not None and abs(cost - best[1]) <= same:
            confirmed = True
        elif best is None or cost < best[1]:
            best, confirmed = (x, cost), False
        if confirmed or best[1] < 1e-24:
            break
    log.debug("corrective triple: cost %.3e (%s)", best[1], "confirmed" if confirmed else "unconfirmed")
    return best[0].reshape(r, 3), float(best[1])


def rotations_from_triple(M: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotations (F, 3, 3) and per-frame coefficients (F,) from ``M_f g ~ c_f R_f``."""
    A = (M @ g).reshape(-1, 2, 3)
    R2, c = nearest_orthonormal_rows(A)
    return complete_rotations(R2), c


def orient_frames(R: np.ndarray, shapes: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Resolve the per-frame sign ambiguity ``(R_f, S_f) ~ (diag(-1, -1, 1) R_f, -S_f)``.

    Both choices give the same image; they differ by reflecting frame f's depth. Each frame is
    turned so that its object-frame shape correlates positively with the dominant shape of the
    sequence (first right singular vector of the F x 3P shape matrix), i.e. the frames deform
    around one common shape instead of its point reflection.

    Parameters
    ----------
    R : (F, 3, 3) float
    shapes : (F, 3, P) float
        Object-frame shapes.

    Returns
    -------
    R, shapes : oriented copies
    sign : (F,) float
        +1 or -1 per frame (the flip applied).
    """
    F = shapes.shape[0]
    flat = shapes.reshape(F, -1)
    v = np.linalg.svd(flat, full_matrices=False)[2][0]
    sign = np.sign(flat @ v)
    sign[sign == 0] = 1.0
    flip = np.array([-1.0, -1.0, 1.0])
    R = np.where(sign[:, None, None] < 0, flip[None, :, None] * R, R)
    return R, shapes * sign[:, None, None], sign
