"""Choosing the combined model's physical residual prior from training data (§6.1).

The combined model (:mod:`lipgen.modes.combined`) reads the observations at DOFs ``o`` as

    y = x̄_o + S_o c + r_o + e,   c ~ (0, Λ_k),   r ~ (0, σ² P),   e ~ (0, τ² I)

with learned modes S (variances Λ_k), a physical prior P (K_s⁻² or K_s⁻¹) for what the modes
cannot express, and observation noise τ². Three things are not given by the modes: the kind of
P, σ² and τ². They are chosen here by **cross-validated marginal likelihood on the training
frames' markers** (the only DOFs training data measure):

1. Split the training frames into ``n_folds`` contiguous blocks (frames next to each other are
   nearly the same, so random splits would only test interpolation in time).
2. For each block, fit the modes on the *other* blocks and score the held-out block's marker
   vectors under the Gaussian N(x̄_o, S_o Λ_k S_oᵀ + σ² P_oo + τ² I) of that fold's model. A
   held-out block holds motion its fold's modes partly have not seen, which is what σ² P is for;
   the isotropic scatter the modes and P both cannot explain is τ².
3. Take the (kind, σ², τ²) with the largest mean held-out log-likelihood per frame, over a grid
   of σ² (a share of the learned variance at ``o``, 8 per decade) and τ² (0, or a share of the
   mean learned variance per observed DOF, 8 per decade).

For one fold and one σ², ``A + σ² P = Q diag(w) Qᵀ`` once; every τ² then costs O(d):
``log det C = Σ log(w + τ²)`` and ``tr(C⁻¹ R) = Σ (Qᵀ R Q)_ii / (w + τ²)`` with R the held-out
scatter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lipgen.modes.model import ModeModel, as_frames

__all__ = ["ResidualPriorSelection", "select_residual_prior", "SHARE_GRID", "NOISE_GRID"]

SHARE_GRID = np.logspace(-5, 1, 49)
"""σ² candidates as a share of the learned variance at the observed DOFs (8 per decade)."""

NOISE_GRID = np.concatenate([[0.0], np.logspace(-8, 0, 65)])
"""τ² candidates as a share of the mean learned variance per observed DOF (0, then 8 per decade)."""


@dataclass(frozen=True)
class ResidualPriorSelection:
    """The chosen physical residual prior and the evidence for it.

    Attributes
    ----------
    kind : str
        "force" (K_s⁻²) or "energy" (K_s⁻¹).
    residual_variance : float
        σ² (mm² per unit of P).
    noise_variance : float
        τ² (mm²), per observed coordinate.
    residual_share : float
        σ² tr(P_oo) / tr(Λ_learned[o, o]): σ² as a share of the learned variance at ``o``.
    log_likelihood : float
        Mean held-out log-likelihood per frame at the choice (nats).
    by_kind : dict
        kind -> {"log_likelihood", "residual_variance", "noise_variance", "residual_share"} at
        that kind's best grid point.
    n_folds : int
    n_frames : int
    n_modes : int
    dofs : (d,) int
        The observed DOFs scored (the markers' by default).
    """

    kind: str
    residual_variance: float
    noise_variance: float
    residual_share: float
    log_likelihood: float
    by_kind: dict
    n_folds: int
    n_frames: int
    n_modes: int
    dofs: np.ndarray


def _fold_statistics(X: np.ndarray, n_modes: int, o: np.ndarray, folds):
    """Per fold: (learned covariance at o (d, d), held-out scatter about the fold mean (d, d), count)."""
    out = []
    for rest, held in folds:
        m = ModeModel(min(n_modes, len(rest) - 1)).fit(X[rest])
        B = np.sqrt(m.explained_variance_)[:, None] * m.components_[:, o]
        r = X[held][:, o] - m.mean_[o]
        out.append((B.T @ B, r.T @ r, len(held)))
    return out


def _loglik_grid(folds, P: np.ndarray, sigma2: np.ndarray, tau2: np.ndarray) -> np.ndarray:
    """(len(sigma2), len(tau2)) mean held-out log-likelihood per frame."""
    d = len(P)
    total = np.zeros((len(sigma2), len(tau2)))
    count = 0
    for A, R, n in folds:
        for i, s2 in enumerate(sigma2):
            w, Q = np.linalg.eigh(A + s2 * P)
            w = np.maximum(w, 0.0)
            rq = np.einsum("ij,ik,kj->j", Q, R, Q)  # diag(Qᵀ R Q)
            lam = w[None, :] + tau2[:, None]  # (t, d)
            with np.errstate(divide="ignore", invalid="ignore"):
                ll = -0.5 * (n * np.sum(np.log(lam), axis=1) + np.sum(rq / lam, axis=1)
                             + n * d * np.log(2 * np.pi))
            total[i] += np.where(np.all(lam > 0, axis=1), ll, -np.inf)
        count += n
    return total / count


def select_residual_prior(U_frames, physics, n_modes: int = 10, dofs=None, n_folds: int = 5,
                          kinds=("force", "energy"), folds=None) -> ResidualPriorSelection:
    """Choose the physical prior kind, σ² and τ² by cross-validated marginal likelihood.

    Parameters
    ----------
    U_frames : (F, n, 3) or (F, 3n) float
        The training fields (mm), e.g. ``Physics.reach`` of each frame's marker goals; only their
        values at ``dofs`` are scored, but each fold's modes are fitted on the whole fields.
    physics : lipgen.Physics
        The reconstruction model (mesh of ``n`` nodes).
    n_modes : int
        Modes of the learned prior (as in the combined model that will use the choice).
    dofs : (d,) int, optional
        Observed DOFs to score; the mesh's marker DOFs by default. Anchored DOFs are dropped.
    n_folds : int
        Contiguous blocks of frames held out in turn (>= 2).
    kinds : tuple of str
        Physical priors to compare: "force" (K_s⁻²) and/or "energy" (K_s⁻¹).

    Returns
    -------
    ResidualPriorSelection
    """
    from lipgen.fem import dofs as node_dofs
    from lipgen.modes.llse import PhysicsCovariance

    X = as_frames(U_frames)
    F, D = X.shape
    if D != physics.n_dofs:
        raise ValueError(f"U_frames have {D // 3} nodes but the physics mesh has {physics.mesh.n_nodes}")
    n_folds = int(n_folds)
    if n_folds < 2:
        raise ValueError(f"n_folds must be >= 2, got {n_folds}")
    if F - (F + n_folds - 1) // n_folds < n_modes + 1:
        raise ValueError(f"{F} frames in {n_folds} folds leave fewer than n_modes + 1 = {n_modes + 1} "
                         "training frames per fold; give more frames or fewer folds")
    mesh = physics.mesh
    o = node_dofs(mesh.markers) if dofs is None else np.asarray(dofs, np.int64)
    o = np.intersect1d(o, physics.free_dofs)
    if len(o) == 0:
        raise ValueError("no free DOFs to score: give the observed (non-anchored) DOFs")
    full = ModeModel(min(n_modes, F - 1)).fit(X)
    B = np.sqrt(full.full_variance_)[:, None] * full.full_components_[:, o]
    learned = float(np.einsum("ij,ij->", B, B))
    if learned <= 0:
        raise ValueError("the training frames do not move at the observed DOFs")
    if folds is None:
        folds = [(np.setdiff1d(np.arange(F), h), h) for h in np.array_split(np.arange(F), n_folds)]
    folds = _fold_statistics(X, n_modes, o, folds)
    tau2 = NOISE_GRID * learned / len(o)
    by_kind = {}
    for kind in kinds:
        P = PhysicsCovariance(physics, 1.0, kind).columns(o)[o]
        P = 0.5 * (P + P.T)
        unit = learned / float(np.trace(P))
        ll = _loglik_grid(folds, P, SHARE_GRID * unit, tau2)
        i, j = np.unravel_index(np.argmax(ll), ll.shape)
        by_kind[kind] = {"log_likelihood": float(ll[i, j]), "residual_variance": float(SHARE_GRID[i] * unit),
                         "noise_variance": float(tau2[j]), "residual_share": float(SHARE_GRID[i])}
    kind = max(by_kind, key=lambda k: by_kind[k]["log_likelihood"])
    best = by_kind[kind]
    return ResidualPriorSelection(kind=kind, by_kind=by_kind, n_folds=n_folds, n_frames=F,
                                  n_modes=int(n_modes), dofs=o, **best)
