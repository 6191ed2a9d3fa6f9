"""Learned modes and estimation from a subset of points (Basu 1997, ch. 4-6, App. B).

* :mod:`~lipgen.modes.model`: :class:`ModeModel`, snapshot PCA of displacement fields (App. B).
* :mod:`~lipgen.modes.llse`: :class:`LLSE`, linear least-squares estimation from any DOF subset (eq 4.7).
* :mod:`~lipgen.modes.residual_prior`: choosing the physical prior of the residual by marginal likelihood.
* :mod:`~lipgen.modes.combined`: :class:`CombinedModel`, learned modes plus a physical residual (§6.1).
* :mod:`~lipgen.modes.mixture`: :class:`ScaleMixtureLLSE`, the residual's size weighed per frame.
"""

from lipgen.modes.combined import DEFAULT_RESIDUAL_SHARE, CombinedModel, default_residual_variance
from lipgen.modes.llse import LLSE, LowRankCovariance, PhysicsCovariance, SumCovariance, llse, pinvh
from lipgen.modes.mixture import MIXTURE_SHARES, ScaleMixtureLLSE
from lipgen.modes.model import ModeModel, as_frames

__all__ = [
    "ModeModel", "as_frames", "LLSE", "llse", "pinvh", "LowRankCovariance", "PhysicsCovariance",
    "SumCovariance", "CombinedModel", "DEFAULT_RESIDUAL_SHARE", "default_residual_variance",
    "ScaleMixtureLLSE", "MIXTURE_SHARES",
]
