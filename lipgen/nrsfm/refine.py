"""Joint refinement of rotations, weights, basis and translation: low-rank bundle adjustment.

Minimises the reprojection error over the observed points,

    sum_{f,p observed} | w_fp - Pi R_f sum_k c_fk b_kp - t_f |^2,

by Levenberg-Marquardt. Per frame the unknowns are a rotation increment (3), the weights (K)
and the image translation (2); per point the K basis positions (3K). Frame unknowns are
eliminated first (small blocks), which leaves a dense 3KP x 3KP system for the basis. Its
frame-summed part factors as ``sum_f (c_f c_f^T) (x) H_f`` with ``H_f`` 3P x 3P, so it is
assembled by one matrix product over frames.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.linalg

from lipgen.nrsfm._rotation import expm_so3

__all__ = ["bundle_adjust"]

log = logging.getLogger(__name__)

_CHUNK = 256  # frames per block when assembling the reduced system (bounds memory)


def _predict(R, C, B, t):
    X = R @ (C @ B.reshape(B.shape[0], -1)).reshape(C.shape[0], 3, -1)
    return X, X[:, :2] + t[:, :, None]


def _frame_jacobian(R, C, B, X, m):
    """d(prediction)/d(frame unknowns), (F, P, 2, K + 5), masked."""
    F, _, P = X.shape
    K = C.shape[1]
    J = np.zeros((F, P, 2, K + 5))
    x0, x1, x2 = X[:, 0], X[:, 1], X[:, 2]
    # d(Pi exp([d]x) X)/dd = -Pi [X]x
    J[:, :, 0, 1], J[:, :, 0, 2] = x2, -x1
    J[:, :, 1, 0], J[:, :, 1, 2] = -x2, x0
    J[:, :, :, 3:3 + K] = np.matmul(R[:, None, :2], B[None]).transpose(0, 3, 2, 1)
    J[:, :, 0, 3 + K] = 1.0
    J[:, :, 1, 4 + K] = 1.0
    return J * m[:, :, None, None]


def bundle_adjust(W: np.ndarray, R: np.ndarray, C: np.ndarray, B: np.ndarray, t: np.ndarray,
                  mask: np.ndarray | None = None, max_iter: int = 100, tol: float = 1e-10):
    """Refine a low-rank reconstruction by Levenberg-Marquardt on the reprojection error.

    Parameters
    ----------
    W : (2F, P) float
        Tracks (unobserved entries ignored).
    R : (F, 3, 3) float
        Rotations.
    C : (F, K) float
        Weights.
    B : (K, 3, P) float
        Basis shapes.
    t : (F, 2) float
        Image translations.
    mask : (F, P) bool, optional
        Observed points.
    max_iter : int
        Iteration cap.
    tol : float
        Stop when an accepted step lowers the cost by less than this fraction.

    Returns
    -------
    R, C, B, t : refined copies
    history : list of float
        Cost (half the sum of squared residuals) after each accepted step, starting value first.
    """
    F, K, P = R.shape[0], C.shape[1], B.shape[2]
    m = np.ones((F, P)) if mask is None else mask.astype(float)
    Wf = W.reshape(F, 2, P) * m[:, None, :]
    nt, nb = K + 5, 3 * K

    def cost_of(R, C, B, t):
        return 0.5 * float((((Wf - _predict(R, C, B, t)[1]) * m[:, None, :]) ** 2).sum())

    cost = cost_of(R, C, B, t)
    history = [cost]
    lam = 1e-4
    eye_t, eye_b = np.eye(nt), np.eye(nb)
    pts = np.arange(P)
    upper = np.triu_indices(K)
    for _ in range(max_iter):
        if cost <= 1e-30:
            break
        X, pred = _predict(R, C, B, t)
        r = (Wf - pred) * m[:, None, :]
        J = _frame_jacobian(R, C, B, X, m)
        Jf = J.reshape(F, 2 * P, nt)
        U = np.matmul(Jf.transpose(0, 2, 1), Jf)
        g_t = np.matmul(Jf.transpose(0, 2, 1), r.transpose(0, 2, 1).reshape(F, 2 * P, 1))[..., 0]
        R2 = R[:, :2]
        G = (J[:, :, 0, :, None] * R2[:, None, None, 0, :] + J[:, :, 1, :, None] * R2[:, None, None, 1, :])
        G = G.transpose(0, 2, 1, 3).reshape(F, nt, 3 * P)
        P2 = np.matmul(R2.transpose(0, 2, 1), R2)
        CC = (C[:, :, None] * C[:, None, :]).reshape(F, K * K)
        CCu = CC.reshape(F, K, K)[:, upper[0], upper[1]]
        kron = (CC.reshape(F, K, 1, K, 1) * P2.reshape(F, 1, 3, 1, 3)).reshape(F, nb * nb)
        V = (m.T @ kron).reshape(P, nb, nb)
        back = np.matmul(R2.transpose(0, 2, 1), r)                       # (F, 3, P)
        g_b = (C.T @ back.reshape(F, -1)).reshape(K, 3, P).transpose(2, 0, 1).reshape(P, nb)
        accepted = False
        while not accepted and lam < 1e12:
            Ud = U + lam * (np.einsum("fii->fi", U)[:, :, None] * eye_t) + 1e-12 * eye_t
            Vd = V + lam * (np.einsum("pii->pi", V)[:, :, None] * eye_b) + 1e-12 * eye_b
            Ui = np.linalg.inv(Ud)
            # sum_f (c_f c_f^T) (x) H_f, for k <= l only (symmetric in k, l)
            Tu = np.zeros((len(upper[0]), 9 * P * P))
            for s in range(0, F, _CHUNK):
                Gs = G[s:s + _CHUNK]
                H = np.matmul(Gs.transpose(0, 2, 1), np.matmul(Ui[s:s + _CHUNK], Gs))
                Tu += CCu[s:s + _CHUNK].T @ H.reshape(len(Gs), -1)
            T = np.empty((K, K, 9 * P * P))
            T[upper] = Tu
            T[upper[1], upper[0]] = Tu.reshape(-1, 3 * P, 3 * P).transpose(0, 2, 1).reshape(len(Tu), -1)
            S = -T.reshape(K, K, P, 3, P, 3).transpose(2, 0, 3, 4, 1, 5).reshape(P * nb, P * nb)
            Sb = S.reshape(P, nb, P, nb)
            Sb[pts, :, pts, :] += Vd
            y = np.matmul(Ui, g_t[..., None])
            Gy = np.matmul(G.transpose(0, 2, 1), y)[..., 0]                 # (F, 3P)
            rhs = (g_b - (C.T @ Gy).reshape(K, P, 3).transpose(1, 0, 2).reshape(P, nb)).ravel()
            try:
                db = scipy.linalg.cho_solve(scipy.linalg.cho_factor(S), rhs)
            except np.linalg.LinAlgError:
                db = np.linalg.lstsq(S, rhs, rcond=None)[0]
            db = db.reshape(P, K, 3)
            Wdb = np.matmul(G, (C @ db.transpose(1, 0, 2).reshape(K, -1))[..., None])[..., 0]
            dth = np.matmul(Ui, (g_t - Wdb)[..., None])[..., 0]
            Rn = expm_so3(dth[:, :3]) @ R
            Cn = C + dth[:, 3:3 + K]
            tn = t + dth[:, 3 + K:]
            Bn = B + db.transpose(1, 2, 0)
            new = cost_of(Rn, Cn, Bn, tn)
            if new < cost:
                accepted = True
                gain = (cost - new) / cost
                R, C, B, t, cost = Rn, Cn, Bn, tn, new
                lam = max(lam / 3, 1e-9)
            else:
                lam *= 4
        history.append(cost)
        if not accepted or gain < tol:
            break
    log.debug("bundle adjustment: %d steps, cost %.3e -> %.3e", len(history) - 1, history[0], cost)
    return R, C, B, t, history
