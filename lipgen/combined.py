"""The combined learned + physical model the thesis proposes in §6.1.

The displacement field is modelled as the sum of two independent parts::

    U = x̄ + U_modes + U_residual,   U_modes ~ (0, S Λ Sᵀ),   U_residual ~ (0, σ² P)

The learned modes S (k, 3n) with variances Λ are the prior for the gross deformation; the
full-rank physics P takes whatever the modes cannot express. The LLSE (eq 4.7) under the summed
covariance then

- reaches any noise-free observation exactly (P is full rank, unlike the rank-k learned
  covariance, which cannot reach a motion outside its span), and
- fills the unobserved DOFs with the learned correlations wherever the modes explain the
  observations, instead of the plain physical smoothing (which knows nothing of how lips move).

As σ² → 0 it becomes the two-stage estimate of §6.1: fit the mode coefficients to the
observations (generalised least squares weighted by the physics), then let the physics reach the
remaining residual. A finite σ² also shrinks the mode coefficients toward their prior, which
keeps a fit to few observations from extrapolating wildly.

The physical prior P: ``kind="force"`` (default) is the thesis's K_s⁻² (eq 4.5: displacements
under IID unit forces; its LLSE alone is the minimum-norm-force field of ``Physics.reach``), i.e.
"the original full-rank physical model" of §6.1. ``kind="energy"`` is K_s⁻¹, the Gaussian whose
negative log-density is the strain energy ½ Uᵀ K_s U (least-strain-energy fill-in). With the
default grounding (strip end and skin border anchored) the two are close and K_s⁻² is slightly
better on the Table 5.1 experiment; with the thesis's strip-only grounding a small force norm buys
large out-of-plane swings, and K_s⁻¹ is far better for partial (x-y or y-z) views.

Choosing σ²: it is the prior variance of motion *outside* the learned span, which the training
set cannot measure (whatever it contained, the modes have kept; its unexplained remainder is only
the truncation and the noise of motions already seen). It is therefore set as a prior share of
the learned variance: at the training observations (the markers) the physics prior carries
``residual_share`` times the variance the learned covariance has there,
``σ² = share · tr(Λ_learned[o, o]) / tr(P[o, o])``. The Table 5.1 experiment chooses the share on
validation motions that hold out other actions than the test motions, and shows the error
against the share.
"""

from __future__ import annotations

import numpy as np

from .llse import LLSE, PhysicsCovariance, SumCovariance

__all__ = ["CombinedModel", "DEFAULT_RESIDUAL_SHARE", "default_residual_variance"]

DEFAULT_RESIDUAL_SHARE = 0.1
"""Prior share of the learned variance given to the physical residual (see the module docstring)."""


def default_residual_variance(modes, physics, share: float = DEFAULT_RESIDUAL_SHARE, dofs=None,
                              kind: str = "force") -> float:
    """σ² = ``share`` · tr(Λ_learned[o, o]) / tr(P[o, o]) (mm² per unit of P).

    ``o`` are ``dofs``, by default the mesh's marker DOFs (what training data really observe),
    all free DOFs if the mesh has no markers; Λ_learned is the full sample covariance and P the
    physical prior of ``kind`` (see :class:`~lipgen.llse.PhysicsCovariance`).
    """
    from .fem import dofs as node_dofs

    modes._check_fitted()
    if not np.isfinite(share) or share <= 0:
        raise ValueError(f"share must be a positive fraction of the learned variance, got {share!r}")
    if dofs is None:
        mesh = physics.mesh
        dofs = node_dofs(mesh.markers) if len(mesh.markers) else physics.free_dofs
    dofs = np.asarray(dofs)
    S = modes.full_components_[:, dofs]
    learned = float(np.sum(modes.full_variance_ * np.einsum("ij,ij->i", S, S)))
    prior = float(np.trace(PhysicsCovariance(physics, 1.0, kind).columns(dofs)[dofs]))
    if learned <= 0:
        raise ValueError("the learned model has no variance at the observed DOFs; give residual_variance")
    return share * learned / prior


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
        σ² (mm² per unit force variance); by default :func:`default_residual_variance` with
        ``residual_share``.
    residual_share : float
        Used when ``residual_variance`` is not given.
    kind : {"force", "energy"}
        The physical prior: K_s⁻² (eq 4.5) or K_s⁻¹ (strain energy).

    Attributes
    ----------
    residual_variance_ : float
        The σ² in use.
    """

    def __init__(self, modes, physics, n_modes: int | None = None, residual_variance: float | None = None,
                 residual_share: float = DEFAULT_RESIDUAL_SHARE, kind: str = "force"):
        modes.check_mesh(physics.mesh)
        self.modes = modes
        self.physics = physics
        self.n_modes = len(modes.components_) if n_modes is None else int(n_modes)
        if residual_variance is None:
            residual_variance = default_residual_variance(modes, physics, residual_share, kind=kind)
        if not np.isfinite(residual_variance) or residual_variance <= 0:
            raise ValueError(f"residual_variance must be a positive variance, got {residual_variance!r}")
        self.residual_variance_ = float(residual_variance)
        self.kind = kind

    def covariance(self) -> SumCovariance:
        """Λ = S Λ_k Sᵀ + σ² P (mm²)."""
        return SumCovariance(self.modes.covariance(self.n_modes),
                             PhysicsCovariance(self.physics, self.residual_variance_, self.kind))

    def llse(self, dofs, noise=0.0) -> LLSE:
        """The precomputed LLSE of all DOFs from ``dofs`` under the combined prior."""
        return LLSE.build(self.covariance(), dofs, mean=self.modes.mean_, noise=noise)
