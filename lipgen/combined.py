"""The combined learned + physical model the thesis proposes in §6.1.

The displacement field is modelled as the sum of two independent parts::

    U = x̄ + U_modes + U_residual,   U_modes ~ (0, S Λ Sᵀ),   U_residual ~ (0, σ² K_s⁻²)

The learned modes S (k, 3n) with variances Λ are the prior for the gross deformation; the
full-rank physics (eq 4.5: displacements under IID forces of variance σ²) takes whatever the modes
cannot express. The LLSE (eq 4.7) under the summed covariance then

- reaches any observation exactly when it is noise-free (K_s⁻² is full rank, unlike the
  rank-k learned covariance, which cannot reach a motion outside its span), and
- fills the unobserved DOFs with the learned correlations wherever the modes explain the
  observations, instead of the plain minimum-strain smoothing of the physics alone (which knows
  nothing of how lips move).

As σ² → 0 it becomes the two-stage estimate of §6.1: fit the mode coefficients to the
observations (generalised least squares weighted by the physics), then let the physics reach the
remaining residual by minimum strain. A finite σ² also shrinks the mode coefficients toward
their prior, which matters with few or noisy observations. σ² is set by the method of moments:
the variance the kept modes leave unexplained at the training observations (the markers) equals
what the physics prior predicts there, ``σ² tr(K_s⁻²[o, o])``.
"""

from __future__ import annotations

import numpy as np

from .llse import LLSE, PhysicsCovariance, SumCovariance

__all__ = ["CombinedModel", "estimate_residual_variance"]


def estimate_residual_variance(modes, physics, n_modes: int | None = None, dofs=None) -> float:
    """Method-of-moments σ² for the physical residual (mm² per unit force variance).

    The variance the first ``n_modes`` modes leave unexplained at ``dofs`` (the mesh's marker DOFs
    by default: what the training data really observed) divided by ``tr(K_s⁻²[dofs, dofs])``.
    """
    from .fem import dofs as node_dofs

    modes._check_fitted()
    k = len(modes.components_) if n_modes is None else int(n_modes)
    if dofs is None:
        markers = physics.mesh.markers
        dofs = node_dofs(markers) if len(markers) else np.arange(physics.mesh.n_dofs)
    dofs = np.asarray(dofs)
    S = modes.full_components_[k:, dofs]
    unexplained = float(np.sum(modes.full_variance_[k:] * np.einsum("ij,ij->i", S, S)))
    C = np.asarray(physics.compliance_columns(dofs))
    prior = float(np.einsum("ij,ij->", C, C))  # tr(K^-2[o, o]) = |K^-1[:, o]|_F^2
    floor = 1e-12 * float(np.sum(modes.full_variance_)) / max(prior, 1e-300)
    return max(unexplained / prior, floor)


class CombinedModel:
    """Learned modes as the prior for the gross deformation, full-rank physics for the residual.

    Parameters
    ----------
    modes : lipgen.modes.ModeModel
        A fitted model on the same mesh as ``physics``.
    physics : lipgen.Physics
        The full-rank physical model (the reconstruction mesh).
    n_modes : int, optional
        Modes used as the learned prior (all kept modes by default).
    residual_variance : float, optional
        σ² (mm² per unit force variance); by default :func:`estimate_residual_variance`.

    Attributes
    ----------
    residual_variance_ : float
        The σ² in use.
    """

    def __init__(self, modes, physics, n_modes: int | None = None, residual_variance: float | None = None):
        modes.check_mesh(physics.mesh)
        self.modes = modes
        self.physics = physics
        self.n_modes = len(modes.components_) if n_modes is None else int(n_modes)
        if residual_variance is None:
            residual_variance = estimate_residual_variance(modes, physics, self.n_modes)
        if not np.isfinite(residual_variance) or residual_variance <= 0:
            raise ValueError(f"residual_variance must be a positive variance, got {residual_variance!r}")
        self.residual_variance_ = float(residual_variance)

    def covariance(self) -> SumCovariance:
        """Λ = S Λ_k Sᵀ + σ² K_s⁻² (mm²)."""
        return SumCovariance(self.modes.covariance(self.n_modes),
                             PhysicsCovariance(self.physics, self.residual_variance_))

    def llse(self, dofs, noise=0.0) -> LLSE:
        """The precomputed LLSE of all DOFs from ``dofs`` under the combined prior."""
        return LLSE.build(self.covariance(), dofs, mean=self.modes.mean_, noise=noise)
