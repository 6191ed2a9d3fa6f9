"""EM Gaussian with missing entries and modes learned from measured markers only (lipgen.modes.missing)."""

import numpy as np
import pytest

from lipgen.modes.missing import em_gaussian, second_difference_noise


def test_em_complete_data_is_the_sample_mean_and_ml_covariance():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(40, 5)) @ rng.normal(size=(5, 5))
    fit = em_gaussian(X, np.ones(X.shape, bool))
    np.testing.assert_allclose(fit.mean, X.mean(0), atol=1e-12)
    np.testing.assert_allclose(fit.covariance, np.cov(X.T, bias=True), atol=1e-12)


def test_em_monotone_bivariate_matches_andersons_closed_form():
    # x1 always observed, x2 on the first m rows: the ML estimate has a closed form (Anderson 1957).
    rng = np.random.default_rng(1)
    n, m = 400, 150
    x1 = rng.normal(2.0, 1.5, n)
    x2 = 0.5 + 0.8 * x1 + rng.normal(0, 0.7, n)
    X = np.stack([x1, x2], 1)
    obs = np.ones_like(X, bool)
    obs[m:, 1] = False
    X[m:, 1] = np.nan
    mu1, s11 = x1.mean(), x1.var()
    b1 = np.cov(x1[:m], x2[:m], bias=True)[0, 1] / x1[:m].var()
    b0 = x2[:m].mean() - b1 * x1[:m].mean()
    s22_1 = np.mean((x2[:m] - b0 - b1 * x1[:m]) ** 2)
    fit = em_gaussian(X, obs, tol=1e-14, max_iter=5000)
    assert fit.converged
    np.testing.assert_allclose(fit.mean, [mu1, b0 + b1 * mu1], rtol=1e-6)
    np.testing.assert_allclose(fit.covariance, [[s11, b1 * s11], [b1 * s11, s22_1 + b1**2 * s11]], rtol=1e-5)
    assert np.all(np.diff(fit.log_likelihood) >= -1e-9 * np.abs(fit.log_likelihood[1:]))


def test_em_loglik_never_decreases_and_needs_two_entries_per_column():
    rng = np.random.default_rng(2)
    X = rng.normal(size=(60, 4)) @ rng.normal(size=(4, 4))
    obs = rng.random(X.shape) > 0.3
    fit = em_gaussian(X, obs)
    assert np.all(np.diff(fit.log_likelihood) >= -1e-9 * np.abs(fit.log_likelihood[1:]))
    obs[:, 2] = False
    obs[0, 2] = True
    with pytest.raises(ValueError, match="columns \\[2\\]"):
        em_gaussian(X, obs)


def test_second_difference_noise_recovers_white_noise_on_a_smooth_signal():
    rng = np.random.default_rng(3)
    t = np.arange(3000) / 30.0
    X = np.stack([np.sin(2 * np.pi * 0.5 * t), np.cos(2 * np.pi * 0.3 * t)], 1) * 5
    X = X + rng.normal(0, [0.3, 0.6], X.shape)
    v = second_difference_noise(X, np.ones(X.shape, bool))
    np.testing.assert_allclose(v, [0.09, 0.36], rtol=0.1)


@pytest.fixture(scope="module")
def physics():
    from lipgen.fem import Physics
    from lipgen.mesh.procedural import lip_mesh

    return Physics(lip_mesh())


def _fields(physics, goals, measured):
    from lipgen.recon.steps import reach_fields

    G = np.where(measured[..., None], goals, np.nan)
    return reach_fields(physics, G, measured, physics.mesh.markers)


def test_fit_measured_with_every_marker_measured_equals_fit(physics):
    from lipgen.modes.model import ModeModel

    rng = np.random.default_rng(4)
    P = len(physics.mesh.markers)
    goals = rng.normal(size=(30, 6)) @ rng.normal(size=(6, 3 * P))
    goals = goals.reshape(30, P, 3)
    meas = np.ones((30, P), bool)
    U = _fields(physics, goals, meas)
    a = ModeModel(5).fit(U, mesh=physics.mesh)
    b = ModeModel(5).fit_measured(U, meas, physics)
    np.testing.assert_allclose(b.mean_, a.mean_, atol=1e-9)
    k = len(a.full_variance_)
    np.testing.assert_allclose(b.full_variance_[:k], a.full_variance_, rtol=1e-7)
    np.testing.assert_allclose(np.abs(b.components_ @ a.components_.T), np.eye(5), atol=1e-6)
    np.testing.assert_array_equal(b.marker_coverage_, np.ones(P))


def test_fit_measured_ignores_the_fill_of_an_unmeasured_marker(physics):
    # Marker 0 is missing in half the frames; the reach fill there is not its value. The EM mean of
    # its goals is the measured frames' regression, the plain fit's is pulled toward the fill.
    from lipgen.modes.model import ModeModel

    rng = np.random.default_rng(5)
    P = len(physics.mesh.markers)
    F = 200
    goals = (rng.normal(size=(F, 8)) @ rng.normal(size=(8, 3 * P))).reshape(F, P, 3)
    goals[:, 0] += 4.0  # the marker sits 4 mm off its interpolation on average
    meas = np.ones((F, P), bool)
    meas[rng.random(F) < 0.5, 0] = False
    U = _fields(physics, goals, meas)
    full = ModeModel(5).fit(_fields(physics, goals, np.ones((F, P), bool)), mesh=physics.mesh)
    plain = ModeModel(5).fit(U, mesh=physics.mesh)
    em = ModeModel(5).fit_measured(U, meas, physics)
    node = 3 * physics.mesh.markers[0] + np.arange(3)
    err_em = np.abs(em.mean_[node] - full.mean_[node]).max()
    err_plain = np.abs(plain.mean_[node] - full.mean_[node]).max()
    assert err_em < 0.1 * err_plain
    assert em.marker_coverage_[0] == pytest.approx(meas[:, 0].mean())


def test_noise_mixture_with_one_noise_level_is_the_textbook_llse():
    from lipgen.modes.llse import LowRankCovariance
    from lipgen.modes.mixture import noise_mixture

    rng = np.random.default_rng(6)
    B = rng.normal(size=(4, 30))
    mean = rng.normal(size=30)
    dofs = np.array([0, 3, 4, 7, 11, 12, 20])
    y = rng.normal(size=(5, len(dofs)))
    r = rng.uniform(0.1, 0.3, len(dofs))
    est = noise_mixture(LowRankCovariance(B), dofs, mean, r, unit=2.0, shares=[0.25])
    C = B.T @ B
    gain = np.linalg.solve(C[np.ix_(dofs, dofs)] + np.diag(r + 0.5), (y - mean[dofs]).T)
    want = mean + (C[:, dofs] @ gain).T
    hid = np.setdiff1d(np.arange(30), dofs)  # at the observed DOFs the extra scatter counts as field
    np.testing.assert_allclose(est.estimate(y).reshape(5, -1)[:, hid], want[:, hid], atol=1e-10)


def test_noise_mixture_weighs_a_gross_outlier_as_noise():
    # A frame far outside the prior puts its weight on the large noise levels and is shrunk toward
    # the mean; a frame drawn from the prior keeps the small ones.
    from lipgen.modes.llse import LowRankCovariance
    from lipgen.modes.mixture import noise_mixture

    rng = np.random.default_rng(7)
    B = rng.normal(size=(3, 24))
    dofs = np.arange(0, 24, 2)
    mix = noise_mixture(LowRankCovariance(B), dofs, np.zeros(24), 0.01, unit=1.0)
    good = (rng.normal(size=3) @ B)[dofs]
    bad = good + rng.normal(0, 20, len(dofs))
    w = mix.weights(np.stack([good, bad]))
    grid = 1.0 * np.logspace(-4, 1, 21)
    assert w[0] @ np.log(grid) < w[1] @ np.log(grid) - 3
