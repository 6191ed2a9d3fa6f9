"""The combined model with a residual of unknown size: LLSE averaged over σ² (a scale mixture).

The combined model (:mod:`lipgen.modes.combined`) reads a frame's observations ``y`` at DOFs ``o`` as

    y = x̄_o + S_o c + r_o + e,   c ~ (0, Λ_k),   r ~ (0, σ² P),   e ~ (0, τ² I)

A single σ² says how far every frame strays from the learned span. Training frames cannot tell
how far a *new* motion will stray: held-out blocks of training frames are still made of the
training motions, so the σ² they choose is the size of the residual of familiar motion, too small
for a motion outside the span (a noisy observation is then read as the learned shape plus noise,
and the new part of the motion is smoothed away).

Here σ² is unknown per frame, with a log-uniform prior over a wide grid σ²_j (a Gaussian scale
mixture: a heavy-tailed residual prior). Each frame's own observations weigh the grid by Bayes::

    w_j(y) ∝ π_j N(y; x̄_o, S_o Λ_k S_oᵀ + σ²_j P_oo + τ² I)

and the estimate is the posterior mean Σ_j w_j(y) x̂_j(y), with x̂_j the LLSE (eq 4.7) under σ²_j.
A frame the modes explain puts its weight on small σ² (the learned correlations fill the hidden
DOFs); a frame they cannot explain moves it to large σ² (the physics reaches what the modes
cannot). Nothing but the frame's own observations enters: no truth, no other test frame. The
estimate is no longer linear in ``y``; its cost is J LLSE products and J Gaussian densities.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from lipgen._validate import as_float_array
from lipgen.modes.llse import LLSE, observed_values
from lipgen.tol import tol

__all__ = ["ScaleMixtureLLSE", "MIXTURE_SHARES", "DiagonalCovariance", "noise_mixture", "NOISE_SHARES"]

MIXTURE_SHARES = np.logspace(-5, 1, 25)
"""σ² grid as a share of the learned variance at the markers (4 per decade; log-uniform prior)."""


def _evidence_factor(C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Q, w) with C = Q diag(w) Qᵀ; w floored at ``tol.rank`` times the largest (C singular)."""
    w, Q = np.linalg.eigh(0.5 * (C + C.T))
    top = max(float(w.max()), np.finfo(float).tiny) if w.size else 1.0
    return Q, np.maximum(w, tol.rank * top)


@dataclass(frozen=True, eq=False)
class ScaleMixtureLLSE:
    """The posterior mean over a grid of residual variances, for one set of observed DOFs.

    Build it with :meth:`build` (or :meth:`lipgen.modes.combined.CombinedModel.mixture`); then
    ``est(values)`` maps observations ``(d,)`` or ``(b, d)`` to fields ``(n, 3)`` or
    ``(b, n, 3)``, like :class:`~lipgen.modes.llse.LLSE`.

    Attributes
    ----------
    dofs : (d,) int
        Observed DOFs.
    variances : (J,) float
        The residual variances σ²_j of the grid (mm² per unit of the residual prior).
    components : tuple of LLSE
        The LLSE under each σ²_j.
    log_prior : (J,) float
        Log prior weight of each σ²_j (normalised).
    factors : tuple of (Q (d, d), w (d,))
        Eigendecompositions of the observed covariance Λ_j[o, o] + R, for the evidence.
    """

    dofs: np.ndarray
    variances: np.ndarray
    components: tuple
    log_prior: np.ndarray
    factors: tuple
    # Stacked so a batch costs one BLAS product: the gains (J*d, 3n) (each component's gain_t
    # becomes a view of its block, so memory is not doubled), offsets (J, 3n), and the evidence
    # whitening [Q_j / sqrt(w_j)] (d, J*d) with its log-determinants (J,).
    _gains: np.ndarray = field(init=False, repr=False)
    _offsets: np.ndarray = field(init=False, repr=False)
    _whiten: np.ndarray = field(init=False, repr=False)
    _logdets: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        put = object.__setattr__
        gains = np.concatenate([c.gain_t for c in self.components], axis=0)
        d = len(self.dofs)
        put(self, "components", tuple(replace(c, gain_t=gains[j * d:(j + 1) * d])
                                      for j, c in enumerate(self.components)))
        put(self, "_gains", gains)
        put(self, "_offsets", np.stack([c.offset for c in self.components]))
        put(self, "_whiten", np.concatenate([Q / np.sqrt(w) for Q, w in self.factors], axis=1))
        put(self, "_logdets", np.array([np.sum(np.log(w)) for _, w in self.factors]))

    @classmethod
    def build(cls, make_covariance, variances, dofs, mean=None, noise=0.0,
              log_prior=None) -> ScaleMixtureLLSE:
        """Precompute the LLSE and the evidence of every σ²_j.

        Parameters
        ----------
        make_covariance : callable
            ``make_covariance(s2)`` returns the prior covariance (mm²) under residual variance ``s2``.
        variances : (J,) float
            The grid σ²_j, positive.
        dofs : (d,) int
            Observed DOFs.
        mean : (3n,) float, optional
            Prior mean (mm).
        noise : float or (d,) float
            Observation-noise variance (mm²).
        log_prior : (J,) float, optional
            Log prior weights (uniform over the grid by default, i.e. log-uniform in σ² for a
            log-spaced grid).
        """
        s2 = as_float_array(variances, "variances", (None,))
        if len(s2) == 0 or (s2 <= 0).any():
            raise ValueError(f"variances must be a non-empty grid of positive variances, got {s2!r} "
                             f"of shape {s2.shape}")
        lp = np.zeros(len(s2)) if log_prior is None else as_float_array(log_prior, "log_prior", (len(s2),))
        lp = lp - np.logaddexp.reduce(lp)
        comps, factors = [], []
        for v in s2:
            est = LLSE.build(make_covariance(float(v)), dofs, mean=mean, noise=noise)
            comps.append(est)
            factors.append(_evidence_factor(est.cross[est.dofs] + np.diag(est.noise)))
        return cls(dofs=comps[0].dofs, variances=s2, components=tuple(comps), log_prior=lp,
                   factors=tuple(factors))

    @property
    def n_nodes(self) -> int:
        return self.components[0].n_nodes

    def _values(self, values) -> np.ndarray:
        return observed_values(values, len(self.dofs))

    def log_evidence(self, values) -> np.ndarray:
        """(b, J) or (J,): log N(y; x̄_o, Λ_j[o, o] + R) of each frame under each σ²_j (nats)."""
        Y = self._values(values)
        R = np.atleast_2d(Y) - self.components[0].mean[self.dofs]
        d, J = len(self.dofs), len(self.factors)
        z = (R @ self._whiten).reshape(len(R), J, d)
        out = -0.5 * (self._logdets + np.einsum("bjd,bjd->bj", z, z) + d * np.log(2 * np.pi))
        return out if Y.ndim == 2 else out[0]

    def weights(self, values) -> np.ndarray:
        """(b, J) or (J,): the posterior weight of each σ²_j given each frame's observations."""
        a = self.log_evidence(values) + self.log_prior
        return np.exp(a - np.logaddexp.reduce(a, axis=-1, keepdims=True))

    def __call__(self, values) -> np.ndarray:
        return self.estimate(values)

    def estimate(self, values) -> np.ndarray:
        """Posterior-mean fields: ``(n, 3)`` for ``values (d,)``, ``(b, n, 3)`` for ``(b, d)`` (mm)."""
        Y = self._values(values)
        Yb = np.atleast_2d(Y)
        W = np.atleast_2d(self.weights(Yb))
        # sum_j w_bj (y_b G_j + o_j) as one product: each frame's weighted copies of its
        # observations (b, J*d) times the stacked gains.
        Z = (W[:, :, None] * Yb[:, None, :]).reshape(len(Yb), -1)
        X = Z @ self._gains + W @ self._offsets
        return X.reshape(*Y.shape[:-1], self.n_nodes, 3)

    def posterior_variance(self, values) -> np.ndarray:
        """(n, 3) or (b, n, 3): each DOF's posterior variance under the mixture (mm²).

        Σ_j w_j (v_j + x̂_j²) − x̂², with v_j the variance under σ²_j alone.
        """
        Y = self._values(values)
        Yb = np.atleast_2d(Y)
        W = np.atleast_2d(self.weights(Yb))
        m1 = np.zeros((len(Yb), 3 * self.n_nodes))
        m2 = np.zeros_like(m1)
        for j, est in enumerate(self.components):
            x = Yb @ est.gain_t + est.offset
            m1 += W[:, j, None] * x
            m2 += W[:, j, None] * (est.posterior_variance().ravel() + x * x)
        var = np.maximum(m2 - m1 * m1, 0.0)
        return var.reshape(*Y.shape[:-1], self.n_nodes, 3)

    def mean_variance(self, values) -> np.ndarray:
        """(b,) or scalar: the posterior-mean σ² of each frame (mm² per unit of the prior)."""
        return self.weights(values) @ self.variances



class DiagonalCovariance:
    """Λ = diag(v): independent scatter per DOF, e.g. observation noise of unknown size.

    Parameters
    ----------
    variances : (3n,) float
        Variance per DOF (mm²), >= 0.
    """

    def __init__(self, variances):
        v = as_float_array(variances, "variances", (None,))
        if len(v) % 3 or (v < 0).any():
            raise ValueError(f"variances must be 3n values >= 0, got shape {v.shape}")
        self.variances = v
        self.n_dofs = len(v)

    def columns(self, dofs) -> np.ndarray:
        """(3n, d): the columns Λ[:, dofs]."""
        dofs = np.asarray(dofs, dtype=np.int64)
        out = np.zeros((self.n_dofs, len(dofs)))
        out[dofs, np.arange(len(dofs))] = self.variances[dofs]
        return out

    def diag_blocks(self, nodes=None) -> np.ndarray:
        """(q, 3, 3) diagonal blocks of Λ (all nodes by default)."""
        v = self.variances.reshape(-1, 3)
        v = v if nodes is None else v[np.asarray(nodes)]
        return np.einsum("qa,ab->qab", v, np.eye(3))

    def matrix(self) -> np.ndarray:
        """(3n, 3n) dense Λ."""
        return np.diag(self.variances)


NOISE_SHARES = np.logspace(-4, 1, 21)
"""Grid of the extra observation noise of :func:`noise_mixture`, as a share of the learned variance
per marker DOF (4 per decade; log-uniform prior)."""


def noise_mixture(covariance, dofs, mean, noise, unit: float, shares=None) -> ScaleMixtureLLSE:
    """The LLSE of a learned prior whose observations carry noise of unknown size, per frame.

    Each frame's observations weigh a log-uniform grid of extra isotropic noise variances
    ``unit · shares`` on top of the measured ``noise`` (Bayes, the evidence
    N(y; x̄_o, Λ_oo + noise + s² I)); the estimate is the posterior mean. A frame the learned
    prior explains keeps the measured noise; a frame it cannot explain (a mis-measured marker, a
    recording normalised askew) is read as noisier, and its observations are trusted less,
    instead of being explained by an extreme mode combination. Only the frame's own observations
    enter (:class:`ScaleMixtureLLSE`). The extra scatter is a diagonal part of the prior, so the
    hidden DOFs' estimate is exactly the LLSE with that noise; at the observed DOFs it counts as
    part of the field (the observations are reproduced more closely there).

    Parameters
    ----------
    covariance : LowRankCovariance
        The learned prior (mm²), 3n DOFs.
    dofs : (d,) int
        Observed DOFs.
    mean : (3n,) float
    noise : float or (d,) float
        Measured observation-noise variance (mm²).
    unit : float
        The learned variance per marker DOF (mm²) the grid is relative to.
    shares : (J,) float, optional
        :data:`NOISE_SHARES` by default.
    """
    from lipgen.modes.llse import SumCovariance

    shares = NOISE_SHARES if shares is None else np.asarray(shares, dtype=np.float64)
    D = int(covariance.n_dofs)

    def make(s2):
        return SumCovariance(covariance, DiagonalCovariance(np.full(D, s2)))

    return ScaleMixtureLLSE.build(make, unit * shares, dofs, mean=mean, noise=noise)
