"""Learning from marker data with gaps: the EM Gaussian and modes that know what was measured.

The thesis learns its modes from least-strain fields (eq 4.3) of frames where every marker was
seen. Through the pipeline a marker is often not accepted in a frame (lost, the views disagree),
and ``reach`` then fills its DOFs with the physics' interpolation of its neighbours. Learned as if
measured, those filled values teach the model that the marker is a fixed linear function of the
others: the learned covariance is (nearly) singular there, and a test frame that does see the
marker asks the LLSE to explain an observation the prior says cannot differ from its
interpolation; with no noise term the gain along the near-null direction is huge.

:func:`em_gaussian` is the maximum-likelihood mean and covariance of a Gaussian from data with
missing entries (EM; Dempster, Laird & Rubin 1977; Little & Rubin, *Statistical Analysis with
Missing Data*, ch. 11): only the measured entries enter the likelihood.

:func:`measured_field_model` uses it where the measurements are, the marker DOFs. A least-strain
field is linear in its marker goals: with every marker a goal, ``U = G m`` for the reach map
``G`` (3n, 3P); a frame whose marker ``j`` was not a goal has the field ``G m'`` where ``m'`` holds
the field's own (interpolated) value at ``j`` (reach with fewer goals is the minimum over a larger
set, and it meets the added goal). So the field distribution is ``G`` applied to the marker
distribution: mean ``G μ`` and covariance ``G Σ Gᵀ``. When every marker was measured in every
frame this is exactly the sample mean and covariance of the fields (up to the unbiased factor
F / (F − 1), applied), so the thesis's modes are unchanged; with gaps, μ and Σ are the EM
estimates from the measured marker DOFs only. A marker measured in no training frame cannot be
learned: its filled values stand (the physics' interpolation) and the model flags it
(:attr:`lipgen.modes.model.ModeModel.marker_coverage_` 0); :func:`lipgen.evaluate.scoring.table51`
does not feed its observations to the learned estimators.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from lipgen._validate import as_float_array

__all__ = ["GaussianFit", "em_gaussian", "measured_field_model", "second_difference_noise"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class GaussianFit:
    """Result of :func:`em_gaussian`.

    Attributes
    ----------
    mean : (D,) float
    covariance : (D, D) float
        Maximum-likelihood (divided by F, not F − 1).
    log_likelihood : (n_iter + 1,) float
        Observed-data log-likelihood before each iteration and at the end (non-decreasing).
    n_iter : int
    converged : bool
    """

    mean: np.ndarray
    covariance: np.ndarray
    log_likelihood: np.ndarray
    n_iter: int
    converged: bool


def _loglik(X, patterns, which, mean, cov) -> float:
    """Observed-data log-likelihood, one factorisation per pattern of measured entries."""
    total = 0.0
    for k, o in enumerate(patterns):
        if not o.any():
            continue
        rows = which == k
        r = X[np.ix_(rows, o)] - mean[o]
        sign, logdet = np.linalg.slogdet(cov[np.ix_(o, o)])
        if sign <= 0:
            return -np.inf
        quad = np.einsum("ij,ji->", r, np.linalg.solve(cov[np.ix_(o, o)], r.T))
        total -= 0.5 * (rows.sum() * (logdet + o.sum() * np.log(2 * np.pi)) + quad)
    return float(total)


def em_gaussian(X, observed, max_iter: int = 200, tol: float = 1e-9) -> GaussianFit:
    """Maximum-likelihood Gaussian from data with missing entries, by EM.

    Parameters
    ----------
    X : (F, D) float
        Data; entries where ``observed`` is False are ignored (may be NaN).
    observed : (F, D) bool
        Which entries were measured. Every column needs at least 2 measured entries.
    max_iter : int
        EM climbs the likelihood monotonically but slowly where much is missing. When some
        measured entries are (nearly) exact linear functions of others, as least-strain fields
        and low-rank motion make them, the likelihood has no maximum: the smallest variances
        shrink toward 0 forever. On the pipeline's training markers (seed 7: one marker measured
        in 35 % of the frames) the log-likelihood went -10910, -98 (5 iterations), 663 (50),
        761 (200), 796 (300), the smallest eigenvalues about 1e-5 mm². Those directions sit far
        below any marker noise, so the LLSE's noise term ignores them; 200 iterations is the budget.
    tol : float
        Stop when the log-likelihood gains less than ``tol`` times its magnitude.

    Returns
    -------
    GaussianFit
        With nothing missing: the sample mean and the ML sample covariance, after one iteration.
    """
    X = as_float_array(X, "X", (None, None), finite=False)
    F, D = X.shape
    obs = np.asarray(observed, dtype=bool)
    if obs.shape != (F, D):
        raise ValueError(f"observed must have shape {(F, D)} like X, got {obs.shape}")
    if not np.isfinite(X[obs]).all():
        raise ValueError(f"X of shape {X.shape} holds NaN or inf at entries marked observed")
    counts = obs.sum(0)
    if (counts < 2).any():
        raise ValueError(f"every column needs >= 2 observed entries; columns "
                         f"{np.flatnonzero(counts < 2).tolist()} of {D} have {counts[counts < 2].tolist()}")
    Xz = np.where(obs, X, 0.0)
    mean = Xz.sum(0) / counts
    var = (np.where(obs, X - mean, 0.0) ** 2).sum(0) / counts
    cov = np.diag(np.maximum(var, 1e-12 * max(var.max(), 1e-300)))
    patterns, which = np.unique(obs, axis=0, return_inverse=True)
    which = which.ravel()
    lls = [_loglik(X, patterns, which, mean, cov)]
    converged = False
    complete = bool(obs.all())   # nothing missing: one step is the sample mean and covariance
    it = 0
    while it < max_iter:
        it += 1
        Xhat = Xz.copy()
        C = np.zeros((D, D))
        for k, o in enumerate(patterns):
            rows = np.flatnonzero(which == k)
            m = ~o
            if not m.any():
                continue
            if not o.any():
                Xhat[np.ix_(rows, m)] = mean[m]
                C[np.ix_(m, m)] += len(rows) * cov[np.ix_(m, m)]
                continue
            Soo = cov[np.ix_(o, o)]
            A = np.linalg.solve(Soo, cov[np.ix_(o, m)]).T  # (m, o): Σ_mo Σ_oo⁻¹
            Xhat[np.ix_(rows, m)] = mean[m] + (X[np.ix_(rows, o)] - mean[o]) @ A.T
            C[np.ix_(m, m)] += len(rows) * (cov[np.ix_(m, m)] - A @ cov[np.ix_(o, m)])
        mean = Xhat.mean(0)
        R = Xhat - mean
        cov = (R.T @ R + C) / F
        cov = 0.5 * (cov + cov.T)
        lls.append(_loglik(X, patterns, which, mean, cov))
        if complete or abs(lls[-1] - lls[-2]) <= tol * max(abs(lls[-1]), 1.0):
            converged = True
            break
    if not converged:
        log.info("em_gaussian: not converged after %d iterations (log-likelihood change %.3g)",
                    max_iter, lls[-1] - lls[-2])
    return GaussianFit(mean, cov, np.asarray(lls), it, converged)


def second_difference_noise(X, observed) -> np.ndarray:
    """Per-column white-noise variance from a time series: ``median(e²) / (1.5 · 0.455)``.

    ``e_t = x_t − (x_{t−1} + x_{t+1}) / 2`` over consecutive frames all three measured. For white
    noise of variance σ², ``e_t`` has variance 1.5 σ²; the median of a χ²₁ is 0.455 of its mean,
    so the median keeps a few fast movements or wrong sightings from inflating it. A smooth motion
    adds its own curvature, so this is an upper bound on the noise.

    Parameters
    ----------
    X : (F, D) float
        Consecutive frames (e.g. normalised marker coordinates, mm).
    observed : (F, D) bool

    Returns
    -------
    (D,) float
        Variance per column (mm²); NaN where no three consecutive frames were measured.
    """
    X = as_float_array(X, "X", (None, None), finite=False)
    obs = np.asarray(observed, dtype=bool)
    if obs.shape != X.shape:
        raise ValueError(f"observed must have shape {X.shape} like X, got {obs.shape}")
    ok = obs[1:-1] & obs[:-2] & obs[2:]
    e = np.where(ok, X[1:-1] - 0.5 * (X[:-2] + X[2:]), np.nan)
    out = np.full(X.shape[1], np.nan)
    has = ok.any(0)
    out[has] = np.nanmedian(e[:, has] ** 2, axis=0) / (1.5 * 0.4549364231195724)
    return out


def measured_field_model(fields, measured, physics) -> dict:
    """Mean and covariance factor of least-strain fields learned from their measured markers only.

    Parameters
    ----------
    fields : (F, n, 3) float
        Least-strain fields of the training frames (finite), mm.
    measured : (F, P) bool
        Which markers were goals (measured) in each frame.
    physics : lipgen.Physics
        The model whose marker nodes (``physics.mesh.markers``, P) the fields reach.

    Returns
    -------
    dict
        ``mean`` (3n,); ``factor`` (3P, 3n) with ``factorᵀ factor`` the unbiased field covariance
        (``G Σ Gᵀ · F / (F − 1)``); ``coverage`` (P,) share of frames each marker was measured;
        ``em`` the :class:`GaussianFit` of the marker DOFs (None if nothing was missing).
    """
    from lipgen.fem import dofs as node_dofs

    mesh = physics.mesh
    U = as_float_array(fields, "fields", (None, mesh.n_nodes, 3))
    F = len(U)
    P = len(mesh.markers)
    meas = np.asarray(measured, dtype=bool)
    if meas.shape != (F, P):
        raise ValueError(f"measured must have shape ({F}, {P}) (frames, markers), got {meas.shape}")
    d = node_dofs(mesh.markers)
    M = U.reshape(F, -1)[:, d]  # (F, 3P): the fields' marker DOFs (goals where measured)
    coverage = meas.mean(0)
    obs = np.repeat(meas | (meas.sum(0) < 2)[None, :], 3, axis=1)  # unlearnable markers: fill stands
    if obs.all():
        mean_m = M.mean(0)
        cov_m = (M - mean_m).T @ (M - mean_m) / F
        em = None
    else:
        em = em_gaussian(M, obs)
        mean_m, cov_m = em.mean, em.covariance
    G = physics.reach(d, np.eye(len(d)))[0].reshape(len(d), -1)  # (3P, 3n): row i = field of unit goal i
    w, V = np.linalg.eigh(0.5 * (cov_m + cov_m.T) * F / (F - 1))
    w = np.clip(w, 0.0, None)
    L = np.sqrt(w)[:, None] * V.T  # (3P, 3P): LᵀL = Σ
    return {"mean": mean_m @ G, "factor": L @ G, "coverage": coverage, "em": em}
