"""EM-PND: NRSfM with a Procrustean normal distribution of shapes (Lee, Cho & Oh, CVPR 2013 / TPAMI 2017).

The idea of the paper: a shape sequence is a rigid motion of *aligned* shapes, and the aligned
shapes ``X_f`` (3 x P) are normally distributed about their mean ``Xbar``, where "aligned" means
Procrustes-aligned to the mean: the rotation that best maps ``X_f`` onto ``Xbar`` is the identity,
i.e. ``X_f Xbar^T`` is symmetric (and ``X_f`` is centred). Every deformation ``D_f = X_f - Xbar``
therefore satisfies the linear *Procrustean constraints*

    D_f 1 = 0                      (3 equations: no translation),
    D_f Xbar^T - Xbar D_f^T = 0    (3 equations: no rotation about the mean),

so a rigid change can never be explained as a deformation: rotations and deformations are
separated strictly, which is what the paper credits for its accuracy. The observations are
``w_fp = c_f Pi R_f (xbar_p + d_fp) + t_f + noise`` (scaled orthography, isotropic Gaussian noise).

EM on this model (as in the paper: E-step = Gaussian posterior of each frame's deformation, M-step =
mean shape, deformation distribution, cameras and noise variance):

- the deformation distribution here is ``d_f = V z_f``, ``z_f ~ N(0, I_K)``, with the K columns
  of V held inside the constraint space above - a rank-K covariance ``V V^T`` (the paper's
  covariance is not tied to a user-set rank; :func:`lipgen.nrsfm.pndk.reconstruct_pnd_auto`
  chooses K from the data, see below). The E-step and the camera, translation and noise
  updates are the EM-PPCA ones of :mod:`.emppca` (the same Gaussian algebra);
- the M-step for ``(Xbar, V)`` is *constrained*: the expected cost is quadratic in them, and the
  bilinear constraint is linear in V for a fixed Xbar and in Xbar for a fixed V, so the step is
  two exact conditional minimisations under the constraints (Lagrange multipliers: one small
  6K x 6K or 3K x 3K system beside the per-point blocks). Each lowers the expected cost (ECM,
  Meng & Rubin 1993), so the marginal likelihood never rises; the adaptive over-relaxation of
  :mod:`.emppca` is kept, its steps projected back onto the constraints and kept only if the
  likelihood improves.

Start and safeguard (:func:`pnd_reconstruction`): EM from the rigid factorisation alone went to
depth-inflated answers on the validation bodies (e3D 1-4 against a flat baseline of 0.5), as
EM-PPCA does, so EM-PND starts from ``dai`` at K + 1 basis shapes (the same rank), aligned by
generalised Procrustes, and its answer is kept only if its depth neither inflates nor roughens
against that start (the truth-free test of ``dai-ba``).

Choosing K without the truth (:func:`lipgen.nrsfm.pndk.reconstruct_pnd_auto`): EM-PND is fitted
on a grid of K and the least Bayesian information criterion (marginal likelihood against the
number of free parameters) among the kept fits wins.
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen.nrsfm._rotation import complete_rotations
from lipgen.nrsfm._tracks import Tracks
from lipgen.nrsfm.emppca import _e_step, _extrapolate, _m_step, _rigid_start

__all__ = ["em_pnd", "pnd_reconstruction", "procrustean_residual", "n_parameters", "bic"]

log = logging.getLogger(__name__)

_PAIRS = ((0, 1), (0, 2), (1, 2))

_EXACT = 1e-6
"""Largest reprojection residual, relative to the largest track coordinate, of a fit that counts as
reproducing noise-free tracks exactly."""


def procrustean_residual(sbar: np.ndarray, V: np.ndarray) -> float:
    """Largest violation of the Procrustean constraints, relative to ``|sbar| |V|``.

    Parameters
    ----------
    sbar : (3, P) float
        Mean shape.
    V : (P, 3, K) float
        Deformation modes.

    Returns
    -------
    float
        ``max(|V_k 1|, |V_k sbar^T - sbar V_k^T|)`` over the modes, scaled; 0 when K = 0.
    """
    if V.shape[2] == 0:
        return 0.0
    Vk = V.transpose(2, 1, 0)                                  # (K, 3, P)
    centre = np.abs(Vk.sum(axis=2)).max()
    cross = Vk @ sbar.T                                        # (K, 3, 3)
    anti = np.abs(cross - cross.transpose(0, 2, 1)).max()
    scale = max(float(np.linalg.norm(sbar) * np.linalg.norm(V)), 1e-300)
    return float(max(centre * np.linalg.norm(sbar), anti)) / scale


def _mode_constraints(sbar: np.ndarray, K: int) -> np.ndarray:
    """Constraint rows on the modes V (P, 3, K), as an array (6K, P, 3, K): per mode k, 3 centring
    rows then the 3 antisymmetric entries of ``V_k sbar^T - sbar V_k^T``."""
    P = sbar.shape[1]
    A = np.zeros((K, 6, P, 3, K))
    for k in range(K):
        for a in range(3):
            A[k, a, :, a, k] = 1.0
        for i, (a, b) in enumerate(_PAIRS):
            A[k, 3 + i, :, a, k] = sbar[b]
            A[k, 3 + i, :, b, k] = -sbar[a]
    return A.reshape(6 * K, P, 3, K)


def _mean_constraints(V: np.ndarray) -> np.ndarray:
    """Constraint rows on the mean shape, as an array (3K, P, 3): per mode k, the antisymmetric
    entries of ``V_k sbar^T - sbar V_k^T`` (linear in sbar for fixed V)."""
    P, _, K = V.shape
    A = np.zeros((K, 3, P, 3))
    for k in range(K):
        for i, (a, b) in enumerate(_PAIRS):
            A[k, i, :, b] = V[:, a, k]
            A[k, i, :, a] = -V[:, b, k]
    return A.reshape(3 * K, P, 3)


def _constrained_blocks(N: np.ndarray, r: np.ndarray, A: np.ndarray) -> np.ndarray:
    """Minimise ``sum_p x_p^T N_p x_p - 2 r_p^T x_p`` subject to ``sum_p A[:, p] x_p = 0``.

    N (P, d, d) positive definite blocks, or one (d, d) block shared by every point; r (P, d),
    A (c, P, d); returns x (P, d). Lagrange: ``x_p = N_p^-1 (r_p - A_p^T lam)`` with
    ``(sum_p A_p N_p^-1 A_p^T) lam = sum_p A_p N_p^-1 r_p`` (solved in the least-squares sense:
    dependent constraints are harmless).
    """
    c, P, d = A.shape
    if N.ndim == 2:  # complete tracks: one normal matrix, every right-hand side in one solve
        sol = np.linalg.solve(N, np.concatenate([r.T, A.reshape(c * P, d).T], axis=1))
        x0, Y = sol[:, :P].T, sol[:, P:].reshape(d, c, P).transpose(2, 0, 1)
    else:
        rhs = np.concatenate([r[..., None], A.transpose(1, 2, 0)], axis=2)     # (P, d, 1 + c)
        sol = np.linalg.solve(N, rhs)
        x0, Y = sol[..., 0], sol[..., 1:]                                      # (P, d), (P, d, c)
    if c == 0:
        return x0
    S = np.einsum("cpd,pde->ce", A, Y)
    g = np.einsum("cpd,pd->c", A, x0)
    lam = np.linalg.lstsq(S, g, rcond=1e-12)[0]
    return x0 - Y @ lam


def _shape_step(Wt, m, G, Zh, ZZ, sbar, V, ridge, complete: bool):
    """The constrained M-step for (sbar, V): V given sbar, then sbar given V (ECM)."""
    F, P = m.shape
    n = Zh.shape[1]
    K = n - 1
    H = np.matmul(G.transpose(0, 2, 1), G)                    # (F, 3, 3)
    back = np.matmul(G.transpose(0, 2, 1), Wt)                # (F, 3, P), Wt masked
    rhs = (back.transpose(2, 1, 0) @ Zh)                      # (P, 3, n)
    if complete:  # one normal matrix shared by every point, (a, k, b, l)
        N = (H.reshape(F, 9).T @ ZZ.reshape(F, n * n)).reshape(3, 3, n, n).transpose(0, 2, 1, 3)
        Nvv = N[:, 1:, :, 1:].reshape(3 * K, 3 * K)
        Nvs, Nsv, Nss = N[:, 1:, :, 0], N[:, 0, :, 1:], N[:, 0, :, 0]
        rv = rhs[:, :, 1:] - np.einsum("akb,pb->pak", Nvs, sbar.T)
    else:
        kron = (H[:, :, None, :, None] * ZZ[:, None, :, None, :]).reshape(F, 9 * n * n)
        N = (m.T @ kron).reshape(P, 3, n, 3, n)               # (p; a, k, b, l)
        Nvv = N[:, :, 1:, :, 1:].reshape(P, 3 * K, 3 * K)
        Nsv, Nss = N[:, :, 0, :, 1:], N[:, :, 0, :, 0]
        rv = rhs[:, :, 1:] - np.einsum("pakb,pb->pak", N[:, :, 1:, :, 0], sbar.T)
    if K:
        V = _constrained_blocks(Nvv + ridge * np.eye(3 * K), rv.reshape(P, 3 * K),
                                _mode_constraints(sbar, K).reshape(6 * K, P, 3 * K)).reshape(P, 3, K)
    if complete:
        rs = rhs[:, :, 0] - np.einsum("abl,pbl->pa", Nsv, V)
    else:
        rs = rhs[:, :, 0] - np.einsum("pabl,pbl->pa", Nsv, V)
    sbar = _constrained_blocks(Nss + ridge * np.eye(3), rs, _mean_constraints(V)).T
    return sbar - sbar.mean(axis=1, keepdims=True), V


def _project_modes(sbar, V):
    """Euclidean projection of the modes onto the constraint space of ``sbar``."""
    P, _, K = V.shape
    if K == 0:
        return V
    A = _mode_constraints(sbar, K).reshape(6 * K, 3 * P * K)
    v = V.reshape(-1)
    lam = np.linalg.lstsq(A @ A.T, A @ v, rcond=1e-12)[0]
    return (v - A.T @ lam).reshape(P, 3, K)


def _start(tracks: Tracks, k: int, n_starts: int, seed: int):
    """Rigid start (Tomasi-Kanade with the corrective triple), modes from the principal components of
    the back-projected rigid residuals, projected onto the Procrustean constraints."""
    F, P = tracks.mask.shape
    m = tracks.mask.astype(float)
    W3 = tracks.W.reshape(F, 2, P)
    Q, c, sbar, t = _rigid_start(tracks, n_starts, seed)
    n_obs2 = 2 * tracks.n_observed
    spread2 = float((((W3 - t[:, :, None]) * m[:, None, :]) ** 2).sum()) / n_obs2
    floor = 1e-18 * spread2
    centre = sbar.mean(axis=1, keepdims=True)
    t = t + np.einsum("fia,a->fi", c[:, None, None] * Q[:, :2], centre[:, 0])
    sbar = sbar - centre
    Wt = (W3 - t[:, :, None]) * m[:, None, :]
    res = (Wt - (c[:, None, None] * Q[:, :2]) @ sbar) * m[:, None, :]
    s2 = max(float((res**2).sum()) / n_obs2, floor)
    back = np.matmul(Q[:, :2].transpose(0, 2, 1), res) / c[:, None, None]
    _, sv, Vt = np.linalg.svd(back.reshape(F, -1), full_matrices=False)
    V = (Vt[:k] * (sv[:k, None] / np.sqrt(F))).reshape(k, 3, P).transpose(2, 1, 0)
    V = _project_modes(sbar, V)
    if k and np.linalg.norm(V) <= 1e-9 * np.sqrt(spread2 * P):
        noise = np.random.default_rng(seed).standard_normal((P, 3, k))
        V = _project_modes(sbar, 1e-3 * np.sqrt(spread2) * noise)
    return (Q, c, sbar, V, t, s2), spread2, floor


def _aligned_start(tracks: Tracks, k: int, shapes: np.ndarray, t: np.ndarray, n_align: int = 10):
    """Start from a reconstruction's camera-frame shapes (F, 3, P) and translations (F, 2): generalised
    Procrustes alignment (rotation per frame) to their mean, then the modes from the principal
    components of the aligned deformations (which satisfy the Procrustean constraints at the
    alignment's fixed point; projected onto them exactly)."""
    F, P = tracks.mask.shape
    m = tracks.mask.astype(float)
    W3 = tracks.W.reshape(F, 2, P)
    n_obs2 = 2 * tracks.n_observed
    Y = shapes - shapes.mean(axis=2, keepdims=True)
    sbar = Y[0]
    for _ in range(n_align):
        U, _, Vt = np.linalg.svd(Y @ sbar.T)                   # R_f = argmax tr(R^T Y_f sbar^T)
        d = np.sign(np.linalg.det(U @ Vt))
        U[:, :, 2] *= d[:, None]
        Q = U @ Vt                                              # Y_f ~ Q_f X_f
        X = np.matmul(Q.transpose(0, 2, 1), Y)
        sbar = X.mean(axis=0)
    spread2 = float((((W3 - t[:, :, None]) * m[:, None, :]) ** 2).sum()) / n_obs2
    floor = 1e-18 * spread2
    D = (X - sbar).reshape(F, -1)
    _, sv, Vt = np.linalg.svd(D, full_matrices=False)
    V = _project_modes(sbar, (Vt[:k] * (sv[:k, None] / np.sqrt(F))).reshape(k, 3, P).transpose(2, 1, 0))
    c = np.ones(F)
    res = ((W3 - t[:, :, None]) - Q[:, :2] @ sbar) * m[:, None, :]
    s2 = max(float((res**2).sum()) / n_obs2 - float((sv[:k] ** 2).sum()) / (F * P) * 2 / 3, 1e-6 * spread2)
    return (Q, c, sbar, V, t, s2), spread2, floor


def em_pnd(tracks: Tracks, k: int, *, max_iter: int = 500, tol: float = 1e-6, n_starts: int = 4,
           seed: int = 0, relax_growth: float = 1.2, relax_max: float = 64.0, start=None):
    """Fit EM-PND with K deformation modes to checked tracks.

    Parameters
    ----------
    tracks : Tracks
        Checked tracks (``check_tracks``); unobserved points are left out of every sum.
    k : int
        Number of deformation modes beyond the mean shape (K >= 0; K = 0 is rigid).
    max_iter : int
        EM iteration cap.
    tol : float
        Stop when an iteration lowers the marginal negative log-likelihood per observed coordinate
        by less than this, or when the noise variance reaches its floor (1e-18 of the spread).
    n_starts, seed : int
        Starts and seed of the rigid initialisation's metric upgrade.
    relax_growth, relax_max : float
        Adaptive over-relaxation (as :func:`lipgen.nrsfm.emppca.em_ppca`); ``relax_growth=1`` is
        plain ECM.

    Returns
    -------
    R : (F, 3, 3) float
        Rotations (object to camera); the object frame is the aligned (Procrustes) frame.
    weights : (F, K + 1) float
        ``c_f [1, E z_f]``: scale times the posterior-mean weights (mean shape first).
    basis : (K + 1, 3, P) float
        Mean shape then the K modes (each centred, each satisfying the Procrustean constraints).
    t : (F, 2) float
        Image translations.
    info : dict
        ``iterations``, ``noise_std``, ``nll`` (first and last, per observed coordinate),
        ``nll_history`` (every iteration's), ``nll_total``, ``converged``, ``procrustean_residual``.
    """
    F, P = tracks.mask.shape
    m = tracks.mask.astype(float)
    W3 = tracks.W.reshape(F, 2, P)
    n_obs2 = 2 * tracks.n_observed
    data = (W3, m, tracks.complete, n_obs2)
    if start is None:
        theta, spread2, floor = _start(tracks, k, n_starts, seed)
    else:
        theta, spread2, floor = _aligned_start(tracks, k, *start)
    ridge = 1e-12 * spread2
    nll, post = _e_step(data, theta)
    history = [float(nll)]
    eta, converged, it = 1.0, False, 0
    for it in range(1, max_iter + 1):  # noqa: B007 (count reported after the loop)
        theta_em = _m_step(data, theta, post, ridge, floor, _shape_step)
        nll_em, post_em = _e_step(data, theta_em)
        trial, nll_new, post_new = theta_em, nll_em, post_em
        if eta > 1.0:  # over-relaxed step, projected back onto the constraints, kept only if better
            Q, c, sbar, V, t, s2 = _extrapolate(theta, theta_em, eta, floor)
            sbar = sbar - sbar.mean(axis=1, keepdims=True)
            over = (Q, c, sbar, _project_modes(sbar, V), t, s2)
            nll_over, post_over = _e_step(data, over)
            if np.isfinite(nll_over) and nll_over < nll_em:
                trial, nll_new, post_new = over, nll_over, post_over
                eta = min(eta * relax_growth, relax_max)
            else:
                eta = 1.0
        else:
            eta = relax_growth
        done = nll - nll_new < tol or trial[5] <= floor
        theta, nll, post = trial, nll_new, post_new
        history.append(float(nll))
        if done:
            converged = True
            break
    Q, c, sbar, V, t, s2 = theta
    Ez = post[0]
    basis = np.concatenate([sbar.T[:, :, None], V], axis=2).transpose(2, 1, 0)   # (K+1, 3, P)
    weights = c[:, None] * np.concatenate([np.ones((F, 1)), Ez], axis=1)
    info = {"iterations": it, "noise_std": float(np.sqrt(s2)), "converged": converged,
            "nll": [history[0], history[-1]], "nll_history": history, "nll_total": float(nll) * n_obs2,
            "procrustean_residual": procrustean_residual(sbar, V)}
    log.debug("EM-PND K=%d: %d iterations, noise std %.3e, converged %s", k, it, np.sqrt(s2), converged)
    return complete_rotations(Q[:, :2]), weights, basis, t, info


def n_parameters(k: int, n_frames: int, n_points: int) -> int:
    """Free parameters of EM-PND with K modes: the centred mean shape (3P - 3), K modes in the
    (3P - 6)-dimensional constraint space less their K(K - 1)/2 rotational freedom, a scaled
    rotation (4) and a translation (2) per frame less the global rotation (3), and the noise (1)."""
    return (3 * n_points - 3) + k * (3 * n_points - 6) - k * (k - 1) // 2 + 6 * n_frames - 3 + 1


def bic(nll_total: float, k: int, n_frames: int, n_points: int, n_coordinates: int) -> float:
    """Bayesian information criterion ``2 NLL + n_parameters log(n)`` (lower is better)."""
    return 2.0 * nll_total + n_parameters(k, n_frames, n_points) * float(np.log(n_coordinates))


def pnd_reconstruction(tracks: Tracks, k: int, start, *, max_iter: int = 500) -> tuple:
    """EM-PND with K modes started from a ``"dai"`` reconstruction of K + 1 basis shapes (the same
    rank-3(K + 1) model), kept only if it stays plausible against that start.

    The start's camera-frame shapes are aligned by generalised Procrustes (:func:`_aligned_start`);
    EM-PND then refines rotations, mean shape and modes. The refinement is kept unless its depth
    inflates or roughens against the start's (:func:`lipgen.nrsfm.plausibility.plausible`, the
    truth-free test ``dai-ba`` uses), or the start is dai's exact K-shape fit (noise-free low-rank
    tracks reproduced exactly) and EM-PND does not reproduce the tracks as exactly; otherwise the
    start is returned.

    Parameters
    ----------
    tracks : Tracks
    k : int
        Deformation modes beyond the mean (K >= 0).
    start : Reconstruction
        ``"dai"`` at K + 1 basis shapes on the same tracks (and scale).
    max_iter : int
        EM iteration cap.

    Returns
    -------
    R : (F, 3, 3), weights : (F, N), basis : (N, 3, P), t : (F, 2), info : dict
        EM-PND's (N = K + 1), or the start's when rejected (``info["pnd_kept"]``).
    """
    from lipgen.nrsfm.plausibility import plausible, shape_figures

    R, C, B, t, info = em_pnd(tracks, k, max_iter=max_iter, start=(start.shapes, start.translation))
    ref = shape_figures(start.rotations, start.object_shapes)
    mine = shape_figures(R, np.einsum("fk,kip->fip", C, B))
    keep = plausible(mine, ref)
    if start.info.get("shapes") == "rank-K fit":
        # the start is dai's exact K-shape fit (noise-free low-rank tracks, reproduced exactly): the
        # closed-form answer, kept unless EM-PND reproduces the tracks as exactly
        F, P = tracks.mask.shape
        pred = np.einsum("fij,fjp->fip", R[:, :2], np.einsum("fk,kip->fip", C, B)) + t[:, :, None]
        res = (tracks.W.reshape(F, 2, P) - pred) * tracks.mask[:, None, :]
        spread = np.abs(tracks.W * np.repeat(tracks.mask, 2, axis=0)).max()
        info["pnd_relative_reprojection"] = float(np.abs(res).max() / max(spread, 1e-300))
        keep = keep and info["pnd_relative_reprojection"] <= _EXACT
    info.update(start_shapes=ref, pnd_shapes=mine, pnd_kept=bool(keep))
    if keep:
        return R, C, B, t, info
    log.info("EM-PND rejected (depth ratio %.3g, depth roughness %.3g against the start's %.3g, %.3g): "
             "returning its dai start", mine["depth_ratio"], mine["depth_roughness"], ref["depth_ratio"],
             ref["depth_roughness"])
    return (start.rotations, start.weights, start.basis, start.translation,
            info | {"start_info": start.info})
