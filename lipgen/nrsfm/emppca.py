"""EM-PPCA: Torresani, Hertzmann & Bregler's probabilistic NRSfM (PAMI 2008, "EM-Gaussian").

Model, per frame f and point p (scaled orthography, isotropic Gaussian noise):

    w_fp = G_f (sbar_p + V_p z_f) + t_f + n_fp,   z_f ~ N(0, I_K),   n_fp ~ N(0, s2 I_2),

with ``G_f = c_f Pi R_f`` (scale c_f > 0 times the first two rows of a rotation), ``sbar`` the
mean shape (3 x P) and ``V`` the K deformation modes (3 x P each). The weights z_f are
latent: EM alternates

- E-step: the Gaussian posterior of z_f given the observed points of frame f (mean, covariance);
- M-step: the mean shape and modes jointly (one 3(K+1) linear system per point), the image
  translations, the cameras (scale in closed form, rotation by Gauss-Newton steps on SO(3)
  with a descent check, so each M-step lowers the expected cost) and the noise variance s2.

EM creeps on this model (camera and shape updates are coupled; with little noise it behaves like
alternating least squares), so the steps are over-relaxed adaptively (Salakhutdinov & Roweis,
ICML 2003): each step moves ``eta`` times as far as EM's, with ``eta`` growing while the marginal
likelihood improves and reset to plain EM when it would not. Fixed points are EM's; on drink and
jaws 500 such steps reach what 2000 plain EM steps reach.

Unobserved points are simply left out of every sum (they are latent like z). The start is the
rigid Tomasi-Kanade factorisation (the corrective triple of :mod:`._rotation` with r = 3) of the
low-rank-completed tracks, with the modes seeded from the principal components of the rigid
residuals back-projected into each frame's image plane.

K here counts deformation modes *beyond* the mean shape: EM-PPCA with K modes is a linear shape
model of K + 1 basis shapes (centred tracks of rank at most 3(K + 1)), i.e. the counterpart of
``method="dai"`` with K + 1 basis shapes. K = 0 is the rigid case.
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen._rotation import rotation_vector as _log_so3
from lipgen.nrsfm._rotation import (
    complete_rotations,
    corrective_triple,
    expm_so3,
    rotations_from_triple,
    skew,
)
from lipgen.nrsfm._tracks import Tracks, complete_tracks, factor

__all__ = ["em_ppca"]

log = logging.getLogger(__name__)

_FLIP = np.diag([-1.0, -1.0, 1.0])


def _rigid_start(tracks: Tracks, n_starts: int, seed: int):
    """Scaled-orthographic rigid factorisation: rotations Q (F,3,3), scales c (F,), shape (3,P), t (F,2)."""
    full = complete_tracks(tracks, 3)
    t = full.mean(axis=1)
    Wc = full - t[:, None]
    M, S3, _ = factor(Wc, 3)
    g, _ = corrective_triple(M, n_starts=n_starts, seed=seed)
    Q, c = rotations_from_triple(M, g)
    shape = np.linalg.solve(g, S3)
    return Q, c, shape, t.reshape(-1, 2)


def _masked_sum(m, X, complete: bool):
    """``m @ X`` (F, n) for a 0/1 mask m (F, P) and X (P, n); one row broadcast when nothing is missing."""
    return np.broadcast_to(X.sum(0), (m.shape[0], X.shape[1])) if complete else m @ X


def _gram(H, V, m, complete: bool):
    """sum over observed points of (G_f V_p)^T (G_f V_p), (F, K, K), from H_f = G_f^T G_f (F, 3, 3)."""
    F, (P, _, K) = H.shape[0], V.shape
    VV = (V[:, :, None, :, None] * V[:, None, :, None, :]).reshape(P, 9 * K * K)   # (p; a, b, k, l)
    MV = _masked_sum(m, VV, complete).reshape(F, 9, K * K)
    return np.matmul(H.reshape(F, 1, 9), MV).reshape(F, K, K)


def _posterior(Wt, m, G, sbar, V, s2, complete: bool):
    """E-step: posterior mean (F, K) and covariance (F, K, K) of z, and terms of the likelihood."""
    F, P, K = G.shape[0], V.shape[0], V.shape[2]
    res = (Wt - G @ sbar) * m[:, None, :]                      # (F, 2, P)
    AtA = _gram(np.matmul(G.transpose(0, 2, 1), G), V, m, complete)
    Minv = np.linalg.inv(AtA + s2 * np.eye(K)[None])
    back = np.matmul(G.transpose(0, 2, 1), res)               # (F, 3, P)
    Atr = back.reshape(F, 3 * P) @ V.transpose(1, 0, 2).reshape(3 * P, K)
    Ez = np.matmul(Minv, Atr[..., None])[..., 0]
    return Ez, s2 * Minv, res, Atr, AtA


def _neg_log_likelihood(res, Atr, Ez, AtA, s2, n_obs2):
    """Marginal negative log-likelihood of the observed coordinates (up to a constant), per coordinate.

    ``w_f ~ N(mean_f, s2 I + A_f A_f^T)``; by the matrix determinant lemma and Woodbury identity
    everything reduces to the K x K matrix ``s2 I + A_f^T A_f``.
    """
    F, K = Ez.shape
    quad = (float((res**2).sum()) - float((Atr * Ez).sum())) / s2
    _, logdet = np.linalg.slogdet(AtA + s2 * np.eye(K)[None])
    return 0.5 * (quad + float(logdet.sum()) + (n_obs2 - F * K) * np.log(s2)) / n_obs2


def _update_shape(Wt, m, G, Zh, ZZ, ridge, complete: bool):
    """M-step for B = [sbar, V] (P, 3, K+1): per point, sum_f m (G_f^T G_f (x) ZZ_f) vec B = rhs."""
    F, P = m.shape
    n = Zh.shape[1]
    D = 3 * n
    H = np.matmul(G.transpose(0, 2, 1), G)
    back = np.matmul(G.transpose(0, 2, 1), Wt)                # (F, 3, P); Wt is masked
    rhs = (back.transpose(2, 1, 0) @ Zh).reshape(P, D)
    if complete:  # one normal matrix shared by every point
        N = (H.reshape(F, 9).T @ ZZ.reshape(F, n * n)).reshape(3, 3, n, n).transpose(0, 2, 1, 3)
        return np.linalg.solve(N.reshape(D, D) + ridge * np.eye(D), rhs.T).T.reshape(P, 3, n)
    kron = (H[:, :, None, :, None] * ZZ[:, None, :, None, :]).reshape(F, D * D)
    N = (m.T @ kron).reshape(P, D, D) + ridge * np.eye(D)[None]
    return np.linalg.solve(N, rhs[..., None])[..., 0].reshape(P, 3, n)


def _mean_shapes(B, Zh):
    """Posterior-mean object shapes ``sum_k Zh_fk B_k``, (F, 3, P)."""
    P, _, n = B.shape
    return (Zh @ B.reshape(P * 3, n).T).reshape(-1, P, 3).transpose(0, 2, 1)


def _camera_terms(Wt, m, B, Zh, ZZ, complete: bool):
    """Expected cost of frame f as a function of G_f: tr(G A G^T) - 2 tr(G C^T) + const."""
    F, P = m.shape
    n = B.shape[2]
    BB = (B[:, :, :, None, None] * B[:, None, None, :, :]).reshape(P, -1)   # (p; a, k, b, l)
    MB = _masked_sum(m, BB, complete).reshape(F, 3, n, 3, n).transpose(0, 1, 3, 2, 4).reshape(F, 9, n * n)
    A = np.matmul(MB, ZZ.reshape(F, n * n, 1)).reshape(F, 3, 3)
    C = np.matmul(Wt, _mean_shapes(B, Zh).transpose(0, 2, 1))  # (F, 2, 3)
    return A, C


def _update_cameras(Q, A, C, n_steps: int = 3):
    """Scaled rotations minimising tr(G A G^T) - 2 tr(G C^T), G = c Pi Q: scale in closed form,
    rotation by Gauss-Newton on the whitened residual (G - C A^-1) L (A = L L^T), with step halving."""
    F = Q.shape[0]
    A = A + 1e-12 * np.trace(A, axis1=1, axis2=2)[:, None, None] * np.eye(3)
    L = np.linalg.cholesky(A)
    target = np.linalg.solve(A, C.transpose(0, 2, 1)).transpose(0, 2, 1) @ L     # G* L, (F, 2, 3)

    def scale_and_cost(Q):
        RL = Q[:, :2] @ L
        c = (RL * target).sum((1, 2)) / (RL * RL).sum((1, 2))
        return c, ((c[:, None, None] * RL - target) ** 2).sum((1, 2))

    c, cost = scale_and_cost(Q)
    gens = skew(np.eye(3))                                     # [e_i]_x, (3, 3, 3)
    for _ in range(n_steps):
        QL = Q @ L
        r = c[:, None, None] * QL[:, :2] - target
        J = c[:, None, None, None] * np.matmul(gens[None, :, :2], QL[:, None])     # (F, 3, 2, 3)
        J = J.reshape(F, 3, 6)
        step = -np.linalg.solve(J @ J.transpose(0, 2, 1) + 1e-12 * np.eye(3), J @ r.reshape(F, 6, 1))[..., 0]
        alpha = np.ones(F)
        for _ in range(6):  # halve the step of frames whose cost would rise
            Qn = expm_so3(alpha[:, None] * step) @ Q
            cn, costn = scale_and_cost(Qn)
            ok = costn <= cost
            if ok.all():
                break
            alpha = np.where(ok, alpha, 0.5 * alpha)
        Q = np.where(ok[:, None, None], Qn, Q)
        c, cost = np.where(ok, cn, c), np.where(ok, costn, cost)
    flip = c < 0                                               # c Pi Q == (-c) Pi diag(-1,-1,1) Q
    Q = np.where(flip[:, None, None], _FLIP @ Q, Q)
    return Q, np.abs(c)


def _e_step(data, theta):
    """Posterior of z and the marginal negative log-likelihood per observed coordinate at theta."""
    W3, m, complete, n_obs2 = data
    Q, c, sbar, V, t, s2 = theta
    Wt = (W3 - t[:, :, None]) * m[:, None, :]
    Ez, cov, res, Atr, AtA = _posterior(Wt, m, c[:, None, None] * Q[:, :2], sbar, V, s2, complete)
    return _neg_log_likelihood(res, Atr, Ez, AtA, s2, n_obs2), (Ez, cov)


def _m_step(data, theta, post, ridge, floor, shape_step=None):
    """Shape, translations, cameras, noise variance, in that order, given the posterior of z.

    ``shape_step(Wt, m, G, Zh, ZZ, sbar, V, ridge, complete) -> (sbar, V)`` replaces the
    unconstrained shape update (EM-PND's constrained one, :mod:`lipgen.nrsfm.empnd`)."""
    W3, m, complete, n_obs2 = data
    Q, c, sbar, V, t, s2 = theta
    Ez, cov = post
    F = W3.shape[0]
    G = c[:, None, None] * Q[:, :2]
    Wt = (W3 - t[:, :, None]) * m[:, None, :]
    Zh = np.concatenate([np.ones((F, 1)), Ez], axis=1)
    ZZ = Zh[:, :, None] * Zh[:, None, :]
    ZZ[:, 1:, 1:] += cov
    if shape_step is None:
        B = _update_shape(Wt, m, G, Zh, ZZ, ridge, complete)      # (P, 3, K+1)
        sbar, V = B[:, :, 0].T, B[:, :, 1:]
    else:
        sbar, V = shape_step(Wt, m, G, Zh, ZZ, sbar, V, ridge, complete)
        B = np.concatenate([sbar.T[:, :, None], V], axis=2)
    mean = _mean_shapes(B, Zh)                                 # (F, 3, P)
    t = ((W3 - G @ mean) * m[:, None, :]).sum(2) / m.sum(1)[:, None]
    Wt = (W3 - t[:, :, None]) * m[:, None, :]
    A, C = _camera_terms(Wt, m, B, Zh, ZZ, complete)
    Q, c = _update_cameras(Q, A, C)
    G = c[:, None, None] * Q[:, :2]
    fit = (Wt - G @ mean) * m[:, None, :]
    spread_z = 0.0
    if V.shape[2]:
        spread_z = float((_gram(np.matmul(G.transpose(0, 2, 1), G), V, m, complete) * cov).sum())
    return Q, c, sbar, V, t, max((float((fit**2).sum()) + spread_z) / n_obs2, floor)


def _extrapolate(theta0, theta1, eta, floor):
    """theta0 + eta (theta1 - theta0): linear in shape and translation, geodesic in rotation,
    geometric in scale and noise variance."""
    Q0, c0, sbar0, V0, t0, s20 = theta0
    Q1, c1, sbar1, V1, t1, s21 = theta1
    Q = expm_so3(eta * _log_so3(Q1 @ Q0.transpose(0, 2, 1))) @ Q0
    return (Q, c0 * (c1 / c0) ** eta, sbar0 + eta * (sbar1 - sbar0), V0 + eta * (V1 - V0),
            t0 + eta * (t1 - t0), max(s20 * (s21 / s20) ** eta, floor))


def em_ppca(tracks: Tracks, k: int, *, max_iter: int = 500, tol: float = 1e-6, n_starts: int = 4,
            seed: int = 0, relax_growth: float = 1.2, relax_max: float = 64.0):
    """Fit EM-PPCA to checked tracks.

    Parameters
    ----------
    tracks : Tracks
        Checked tracks (``check_tracks``); unobserved points are left out of every sum.
    k : int
        Number of deformation modes beyond the mean shape (K >= 0).
    max_iter : int
        EM iteration cap.
    tol : float
        Stop when an iteration lowers the marginal negative log-likelihood per observed coordinate
        by less than this, or when the noise std falls below 1e-9 of the track spread.
    n_starts, seed : int
        Starts and seed of the rigid initialisation's metric upgrade.
    relax_growth, relax_max : float
        Adaptive over-relaxation: after each step that lowered the likelihood-based cost, the next
        step goes ``eta`` times as far as EM's (``eta`` grows by ``relax_growth`` up to
        ``relax_max``); a step that does not lower it is replaced by the plain EM step and ``eta``
        falls back to 1. ``relax_growth=1`` gives plain EM.

    Returns
    -------
    R : (F, 3, 3) float
        Rotations (object to camera).
    weights : (F, K + 1) float
        ``c_f [1, E z_f]``: the scale times the posterior-mean weights (mean shape first).
    basis : (K + 1, 3, P) float
        Mean shape then modes, each centred over the points.
    t : (F, 2) float
        Image translations.
    info : dict
        ``iterations``, ``noise_std``, ``nll`` (first and last), ``converged``.
    """
    F, P = tracks.mask.shape
    m = tracks.mask.astype(float)
    complete = tracks.complete
    W3 = tracks.W.reshape(F, 2, P)
    n_obs2 = 2 * tracks.n_observed
    Q, c, sbar, t = _rigid_start(tracks, n_starts, seed)
    spread2 = float((((W3 - t[:, :, None]) * m[:, None, :]) ** 2).sum()) / n_obs2
    floor = 1e-18 * spread2
    Wt = (W3 - t[:, :, None]) * m[:, None, :]
    res = (Wt - (c[:, None, None] * Q[:, :2]) @ sbar) * m[:, None, :]
    s2 = max(float((res**2).sum()) / n_obs2, floor)
    # modes seeded from the principal components of the back-projected rigid residuals
    back = np.matmul(Q[:, :2].transpose(0, 2, 1), res) / c[:, None, None]
    _, sv, Vt = np.linalg.svd(back.reshape(F, -1), full_matrices=False)
    V = (Vt[:k] * (sv[:k, None] / np.sqrt(F))).reshape(k, 3, P).transpose(2, 1, 0)   # (P, 3, K)
    if k and not np.any(V):
        V = 1e-3 * np.sqrt(spread2) * np.random.default_rng(seed).standard_normal((P, 3, k))
    ridge = 1e-12 * spread2
    data = (W3, m, complete, n_obs2)
    theta = (Q, c, sbar, V, t, s2)
    nll, post = _e_step(data, theta)
    history = [nll]
    eta, converged, it = 1.0, False, 0
    for it in range(1, max_iter + 1):  # noqa: B007 (count reported after the loop)
        theta_em = _m_step(data, theta, post, ridge, floor)
        if eta > 1.0:  # adaptive over-relaxation (Salakhutdinov & Roweis 2003), kept only if it helps
            trial = _extrapolate(theta, theta_em, eta, floor)
            nll_new, post_new = _e_step(data, trial)
            if np.isfinite(nll_new) and nll_new < nll:
                eta = min(eta * relax_growth, relax_max)
            else:
                trial, eta = theta_em, 1.0
                nll_new, post_new = _e_step(data, trial)
        else:
            trial = theta_em
            nll_new, post_new = _e_step(data, trial)
            eta = relax_growth
        done = nll - nll_new < tol or trial[5] <= floor
        theta, nll, post = trial, nll_new, post_new
        history.append(nll)
        if done:
            converged = True
            break
    Q, c, sbar, V, t, s2 = theta
    Wt = (W3 - t[:, :, None]) * m[:, None, :]
    Ez = _posterior(Wt, m, c[:, None, None] * Q[:, :2], sbar, V, s2, complete)[0]
    basis = np.concatenate([sbar.T[:, :, None], V], axis=2).transpose(2, 1, 0)   # (K+1, 3, P)
    weights = c[:, None] * np.concatenate([np.ones((F, 1)), Ez], axis=1)
    centre = basis.mean(axis=2)                                # (K+1, 3)
    basis = basis - centre[:, :, None]
    t = t + np.einsum("fia,fa->fi", Q[:, :2], weights @ centre)
    info = {"iterations": it, "noise_std": float(np.sqrt(s2)), "converged": converged,
            "nll": [history[0], history[-1]] if history else []}
    log.debug("EM-PPCA K=%d: %d iterations, noise std %.3e, converged %s", k, it, np.sqrt(s2), converged)
    return complete_rotations(Q[:, :2]), weights, basis, t, info
