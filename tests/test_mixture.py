"""The scale-mixture estimate (lipgen.modes.mixture): Bayes over a grid of residual variances."""

import numpy as np
import pytest

from lipgen import Physics, dofs, lip_mesh
from lipgen.modes.combined import CombinedModel
from lipgen.modes.llse import LLSE, LowRankCovariance, PhysicsCovariance, SumCovariance
from lipgen.modes.mixture import ScaleMixtureLLSE
from lipgen.modes.model import ModeModel


@pytest.fixture(scope="module")
def physics():
    return Physics(lip_mesh(0))


@pytest.fixture(scope="module")
def setup(physics):
    """A random 4-mode learned factor B and the dense K_s^-2 (test-only reference)."""
    rng = np.random.default_rng(5)
    B = np.zeros((4, physics.n_dofs))
    B[:, physics.free_dofs] = rng.normal(size=(4, len(physics.free_dofs)))
    P = PhysicsCovariance(physics).matrix()
    return B, P


def _make(physics, B):
    return lambda s2: SumCovariance(LowRankCovariance(B), PhysicsCovariance(physics, s2))


def _gauss_logpdf(y, C):
    sign, logdet = np.linalg.slogdet(C)
    assert sign > 0
    return -0.5 * (logdet + y @ np.linalg.solve(C, y) + len(y) * np.log(2 * np.pi))


def test_weights_and_estimate_are_bayes_over_the_grid(physics, setup):
    """Closed form: w_j ∝ π_j N(y; x̄_o, Λ_j[o,o] + R) and x̂ = Σ w_j Λ_j[:,o](Λ_j[o,o] + R)⁻¹(y − x̄_o)."""
    B, P = setup
    rng = np.random.default_rng(0)
    d = dofs(physics.mesh.markers[:6], "xy")
    mean = np.zeros(physics.n_dofs)
    mean[physics.free_dofs] = rng.normal(scale=0.1, size=len(physics.free_dofs))
    s2 = np.array([1e-3, 1e-1, 10.0])
    prior = np.log([0.5, 0.3, 0.2])
    est = ScaleMixtureLLSE.build(_make(physics, B), s2, d, mean=mean, noise=0.05, log_prior=prior)
    y = mean[d] + rng.normal(scale=2.0, size=len(d))
    lw, xs = [], []
    for v, lp in zip(s2, prior, strict=True):
        S = B.T @ B + v * P
        C = S[np.ix_(d, d)] + 0.05 * np.eye(len(d))
        lw.append(lp + _gauss_logpdf(y - mean[d], C))
        xs.append(mean + S[:, d] @ np.linalg.solve(C, y - mean[d]))
    w = np.exp(np.array(lw) - np.logaddexp.reduce(lw))
    assert np.allclose(est.weights(y), w, atol=1e-9)
    want = np.einsum("j,jd->d", w, np.array(xs))
    assert np.allclose(est(y).ravel(), want, atol=1e-8 * np.abs(want).max())
    # A batch gives each frame its own weights.
    Y = np.stack([y, mean[d] + 1e-3 * rng.normal(size=len(d))])
    assert np.allclose(est(Y)[0], est(y)) and np.allclose(est(Y)[1], est(Y[1]))
    assert est.weights(Y).shape == (2, 3)
    # The components' gains are views of the stacked gains, not copies.
    assert all(np.shares_memory(c.gain_t, est._gains) for c in est.components)
    assert np.allclose(est.mean_variance(Y), est.weights(Y) @ s2)


def test_one_variance_is_the_llse(physics, setup):
    B, _ = setup
    d = dofs(physics.mesh.markers[:8])
    y = np.random.default_rng(1).normal(size=(3, len(d)))
    mix = ScaleMixtureLLSE.build(_make(physics, B), [0.2], d, noise=0.01)
    one = LLSE.build(_make(physics, B)(0.2), d, noise=0.01)
    assert np.allclose(mix(y), one(y), atol=1e-10) and np.allclose(mix.weights(y), 1.0)
    assert np.allclose(mix.posterior_variance(y), one.posterior_variance()[None], atol=1e-10)


def test_the_frame_picks_its_residual_size(physics, setup):
    """Frames drawn with a small residual weigh small σ², frames with a large one large σ²; with
    every DOF observed and no noise, the estimate returns the observations whatever the weights."""
    B, P = setup
    rng = np.random.default_rng(2)
    d = dofs(physics.mesh.markers)
    s2 = np.logspace(-4, 2, 13)
    est = ScaleMixtureLLSE.build(_make(physics, B), s2, d, noise=1e-6)
    L = np.linalg.cholesky(P[np.ix_(d, d)] + 1e-12 * np.eye(len(d)))
    coef = rng.normal(size=(20, 4))
    for true in (1e-3, 10.0):
        Y = coef @ B[:, d] + np.sqrt(true) * rng.normal(size=(20, len(d))) @ L.T
        picked = np.exp(np.log(s2) @ est.weights(Y).T)  # posterior geometric-mean σ² per frame
        assert np.all(np.abs(np.log10(picked / true)) < 1.0), (true, picked)
    free = physics.free_dofs
    full = ScaleMixtureLLSE.build(_make(physics, B), [1e-3, 1.0], free)
    y = rng.normal(size=(2, len(free)))
    assert np.allclose(full(y).reshape(2, -1)[:, free], y, atol=1e-6)
    post = full.posterior_variance(y).reshape(2, -1)[:, free]
    assert np.all(post >= 0) and np.allclose(post, 0, atol=1e-8)


def test_combined_model_mixture(physics):
    rng = np.random.default_rng(3)
    U = rng.normal(size=(30, physics.n_dofs))
    U[:, physics.anchored_dofs] = 0
    cm = CombinedModel(ModeModel(5).fit(U, mesh=physics.mesh), physics, noise_variance=0.02)
    d = dofs(physics.mesh.markers, "yz")
    mix = cm.mixture(d, shares=[0.1])
    y = U[:4, d]
    one = CombinedModel(cm.modes, physics, residual_share=0.1, noise_variance=0.02).llse(d)
    assert np.allclose(mix(y), one(y))
    assert np.allclose(mix.components[0].noise, 0.02)
    assert len(cm.mixture(d).variances) == 25


def test_bad_input(physics, setup):
    B, _ = setup
    d = dofs(physics.mesh.markers[:4])
    with pytest.raises(ValueError, match="positive variances"):
        ScaleMixtureLLSE.build(_make(physics, B), [0.1, -1.0], d)
    with pytest.raises(ValueError, match="positive variances"):
        ScaleMixtureLLSE.build(_make(physics, B), [], d)
    est = ScaleMixtureLLSE.build(_make(physics, B), [0.1, 1.0], d)
    with pytest.raises(ValueError, match=r"values must have shape \(12,\)"):
        est(np.zeros(11))
    with pytest.raises(ValueError, match="NaN or inf"):
        est(np.full(12, np.nan))
