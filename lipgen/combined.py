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
default grounding (strip end and skin border anchored) the two are close; with the thesis's
strip-only grounding a small force norm buys large out-of-plane swings, and K_s⁻¹ is far better
for partial (x-y or y-z) views.

Choosing the prior kind, σ² and the noise variance τ² (:meth:`CombinedModel.fit`, by
:func:`lipgen.residual_prior.select_residual_prior`): from the *training* fields only, by
cross-validated marginal likelihood of the training frames' markers. The frames are cut into 5
contiguous blocks; each block's 48 marker coordinates are scored under the Gaussian
N(x̄_o, S_o Λ_k S_oᵀ + σ² P_oo + τ² I) of modes fitted on the other blocks, and the (kind, σ², τ²)
of the largest mean held-out log-likelihood wins (grid: σ² from 1e-5 to 10 times the learned
variance at the markers, τ² = 0 or 1e-8 to 1 times the mean learned variance per marker DOF,
8 steps per decade). A held-out block holds motion that the other blocks' modes have partly not
seen, which is what σ² P stands for; τ² is the isotropic scatter neither explains (marker noise,
and the mismatch between the truth and the model's physics). Training frames only: nothing of
the test motions enters.

Measured on the Table 5.1 experiment (``lipgen experiment table51``, seed 0, 140 training
frames, 10 modes, the synthetic subject with one-sided actions; held-out log-likelihoods per frame):

- noise-free markers: K_s⁻² (19.4 nats against 0.0 for the best K_s⁻¹), σ² = 0.032 of the
  learned variance at the markers, τ² = 0; trained without the smile and the funneler: K_s⁻²,
  σ² share 0.010, τ² = 0;
- 0.3 mm marker noise (true τ² = 0.09 mm²): K_s⁻² (−36.6 against −38.2), σ² share 0.24,
  τ² = 0.067 mm²; without the smile and the funneler: σ² share 0.075, τ² = 0.094 mm². The noise
  is found to within 5-25 %; the rest of it is read as physical residual.

How reliably it beats both, on 12 small random realisations of the held-out-action protocol
(140 training frames without the smile and the funneler, test frames that use them; seeds
0-11, ``tests/test_physics_prior.py``), as the geometric mean of the combined error over the best
learned-only (10 modes or full covariance) and over the best physics-only (K_s⁻² or K_s⁻¹) error
of each row, and how often it wins:

====================  ==========================  ==========================
row                   noise-free                  0.3 mm marker noise
====================  ==========================  ==========================
xyz (8 points)        0.89 (10/12), 0.83 (12/12)  0.91 (11/12), 0.89 (11/12)
yz (16 points)        0.59 (10/12), 0.80 (8/12)   0.93 (10/12), 0.82 (9/12)
xy (16 points)        0.89 (6/12), 0.67 (11/12)   0.95 (7/12), 0.71 (11/12)
====================  ==========================  ==========================

(each cell: against learned-only, against physics-only.) The full experiment (head motion, 40
test frames per realisation, 8 realisations; ``lipgen experiment table51``) is less kind:

====================  ==========================  ==========================
row                   noise-free                  0.3 mm marker noise
====================  ==========================  ==========================
xyz (8 points)        0.77 (8/8), 0.89 (7/8)      0.88 (7/8), **1.08** (3/8)
yz (16 points)        0.62 (7/8), 0.57 (7/8)      0.86 (8/8), 0.68 (6/8)
xy (16 points)        **1.09** (3/8), 0.40 (8/8)  0.97 (4/8), 0.61 (8/8)
====================  ==========================  ==========================

So it does not beat both in every row: from an x-y (frontal) view it is on average no better than
the learned modes alone, and from 8 noisy points no better than the physics alone. Why x-y: the
frontal view cannot see depth, and the held-out smile and funneler move the lips much in depth;
the x-y residual that the modes leave does not tell the physics how the hidden DOFs moved. Even
the plain two-stage estimate (the learned-only LLSE, then the physical reach of its x-y residual
at the markers) is 1.02 times the learned-only error on the same 8 realisations: the physical
correction of the frontal residual does not help on average (it does help from y-z and from 8
points, where the joint LLSE here gains 38 % and 23 % on the learned-only error).

Before, the share was a fixed 0.1 (0.01 or 1.0 picked on validation motions of held-out actions)
with no noise variance: with noisy markers the full-rank prior then reaches every observation
exactly and chases the noise. τ² is now passed to the LLSE by default (``llse(dofs)`` uses
``noise_variance_``). Leave-*actions*-out folds (hold out the frames where one action is active,
train on those where it is quiet; ``fit(folds=...)`` takes any split) chose larger shares (0.32
noise-free, 0.56 noisy) with no consistent gain on the held-out actions of Table 5.1 (xyz / yz /
xy, mm²: noise-free 0.209 / 0.268 / 0.320 against 0.208 / 0.274 / 0.323 with the blocks; noisy
0.253 / 0.350 / 0.377 against 0.256 / 0.346 / 0.353), and they need action labels that real
marker data do not have, so the blocks are the default. ``renders/table51/report.md`` has the
errors of one realisation, row by row, with the rows where the combined model does not beat both.

Without :meth:`CombinedModel.fit`, σ² is a prior share of the learned variance at the markers
(:func:`default_residual_variance`) and τ² = 0.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .llse import LLSE, PhysicsCovariance, SumCovariance

if TYPE_CHECKING:
    from .mixture import ScaleMixtureLLSE

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
        σ² (mm² per unit of P); by default :func:`default_residual_variance` with
        ``residual_share``. :meth:`fit` chooses it from training data instead.
    residual_share : float
        Used when ``residual_variance`` is not given.
    kind : {"force", "energy"}
        The physical prior: K_s⁻² (eq 4.5) or K_s⁻¹ (strain energy).
    noise_variance : float
        Observation-noise variance τ² (mm²) that :meth:`llse` uses by default.

    Attributes
    ----------
    residual_variance_ : float
        The σ² in use.
    noise_variance_ : float
        The τ² in use (mm²).
    selection_ : lipgen.residual_prior.ResidualPriorSelection
        After :meth:`fit`: the choice and its held-out log-likelihoods.
    """

    def __init__(self, modes, physics, n_modes: int | None = None, residual_variance: float | None = None,
                 residual_share: float = DEFAULT_RESIDUAL_SHARE, kind: str = "force",
                 noise_variance: float = 0.0):
        modes.check_mesh(physics.mesh)
        self.modes = modes
        self.physics = physics
        self.n_modes = len(modes.components_) if n_modes is None else int(n_modes)
        if residual_variance is None:
            residual_variance = default_residual_variance(modes, physics, residual_share, kind=kind)
        if not np.isfinite(residual_variance) or residual_variance <= 0:
            raise ValueError(f"residual_variance must be a positive variance, got {residual_variance!r}")
        if not np.isfinite(noise_variance) or noise_variance < 0:
            raise ValueError(f"noise_variance must be a variance >= 0 (mm^2), got {noise_variance!r}")
        self.residual_variance_ = float(residual_variance)
        self.noise_variance_ = float(noise_variance)
        self.kind = kind

    def fit(self, U_frames, dofs=None, n_folds: int = 5, kinds=("force", "energy"),
            folds=None) -> CombinedModel:
        """Choose the prior kind, σ² and τ² from training fields (see the module docstring).

        Parameters
        ----------
        U_frames : (F, n, 3) or (F, 3n) float
            The training fields the modes were learned from (mm), e.g. the reach fields of the
            training frames' markers.
        dofs : (d,) int, optional
            The DOFs training data measure (the marker DOFs by default).
        n_folds : int
            Contiguous blocks of frames held out in turn.
        kinds : tuple of str
            Physical priors to choose from.
        folds : list of (train_idx, held_idx), optional
            Another split of the frames (e.g. leave-actions-out) instead of the blocks.
        """
        from .residual_prior import select_residual_prior

        sel = select_residual_prior(U_frames, self.physics, self.n_modes, dofs=dofs, n_folds=n_folds,
                                    kinds=kinds, folds=folds)
        self.kind = sel.kind
        self.residual_variance_ = sel.residual_variance
        self.noise_variance_ = sel.noise_variance
        self.selection_ = sel
        return self

    def covariance(self) -> SumCovariance:
        """Λ = S Λ_k Sᵀ + σ² P (mm²)."""
        return SumCovariance(self.modes.covariance(self.n_modes),
                             PhysicsCovariance(self.physics, self.residual_variance_, self.kind))

    def llse(self, dofs, noise=None) -> LLSE:
        """The precomputed LLSE of all DOFs from ``dofs`` under the combined prior.

        ``noise`` (mm², scalar or per DOF) defaults to ``noise_variance_``; pass 0 for exact
        observations.
        """
        noise = self.noise_variance_ if noise is None else noise
        return LLSE.build(self.covariance(), dofs, mean=self.modes.mean_, noise=noise)

    def mixture(self, dofs, noise=None, shares=None) -> ScaleMixtureLLSE:
        """The estimate of all DOFs from ``dofs`` with σ² unknown per frame (a scale mixture).

        Each frame's observations weigh a log-uniform grid of residual variances, σ²_j =
        ``shares`` × the learned variance at the markers per unit of P (see
        :mod:`lipgen.mixture`); the estimate is the posterior mean over the grid. Use it for
        motion that may lie outside the training span; :meth:`llse` (one σ², linear) for motion
        like the training frames.

        Parameters
        ----------
        dofs : (d,) int
            Observed DOFs.
        noise : float or (d,) float, optional
            Observation-noise variance (mm²); ``noise_variance_`` by default.
        shares : (J,) float, optional
            The grid as shares of the learned variance; :data:`lipgen.mixture.MIXTURE_SHARES` by
            default (1e-5 to 10, 4 per decade).
        """
        from .mixture import MIXTURE_SHARES, ScaleMixtureLLSE

        noise = self.noise_variance_ if noise is None else noise
        shares = MIXTURE_SHARES if shares is None else np.asarray(shares, dtype=np.float64)
        unit = default_residual_variance(self.modes, self.physics, 1.0, kind=self.kind)
        learned = self.modes.covariance(self.n_modes)

        def make(s2):
            return SumCovariance(learned, PhysicsCovariance(self.physics, s2, self.kind))

        return ScaleMixtureLLSE.build(make, unit * shares, dofs, mean=self.modes.mean_, noise=noise)
