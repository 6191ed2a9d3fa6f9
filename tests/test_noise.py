"""Integer sensor noise (lipgen.rig.noise) against the rounded Gaussian it replaces."""

import math

import numpy as np
import pytest

from lipgen.rig.noise import add_rounded_gaussian, rounded_gaussian, rounded_gaussian_pmf

SIGMAS = [0.3, 1.0, 3.7, 32.0]


@pytest.mark.parametrize("sigma", SIGMAS)
def test_pmf_is_the_rounded_gaussian(sigma):
    k, p = rounded_gaussian_pmf(sigma)
    assert p.sum() == pytest.approx(1.0, abs=1e-14)
    np.testing.assert_allclose(p, p[::-1], atol=1e-15)  # symmetric about 0
    # closed form: P(k) = (erf((k+.5)/(s sqrt2)) - erf((k-.5)/(s sqrt2))) / 2
    r = math.sqrt(2) * sigma
    want = [(math.erf((x + 0.5) / r) - math.erf((x - 0.5) / r)) / 2 for x in k]
    np.testing.assert_allclose(p, want, rtol=1e-9, atol=1e-15)
    # the variance of round(sigma z) is sigma^2 + 1/12 (Sheppard) for sigma >~ 1
    if sigma >= 1:
        assert (k**2 * p).sum() == pytest.approx(sigma**2 + 1 / 12, rel=1e-6)


def _bins(k, p, counts, n, min_expected=20.0):
    """Merge the tails into bins each expecting at least ``min_expected`` counts."""
    obs, exp, o, e = [], [], 0.0, 0.0
    for c, q in zip(counts, p * n, strict=True):
        o, e = o + c, e + q
        if e >= min_expected:
            obs.append(o)
            exp.append(e)
            o, e = 0.0, 0.0
    obs[-1] += o
    exp[-1] += e
    return np.array(obs), np.array(exp)


@pytest.mark.parametrize("sigma", SIGMAS)
def test_draws_follow_the_pmf(sigma):
    n = 2_000_000
    k, p = rounded_gaussian_pmf(sigma)
    x = rounded_gaussian((n,), sigma, np.random.default_rng(5))
    assert x.dtype == np.int16
    counts = np.bincount(x.astype(np.int64) - k[0], minlength=len(k))
    obs, exp = _bins(k, p, counts, n)
    chi2 = ((obs - exp) ** 2 / exp).sum()
    dof = len(obs) - 1
    assert chi2 < dof + 5 * math.sqrt(2 * dof)  # a chi-square more than 5 sd above its mean fails
    assert abs(x.mean()) < 5 * math.sqrt((k**2 * p).sum() / n)
    var = (k**2 * p).sum()
    assert x.var() == pytest.approx(var, rel=5 * math.sqrt(2 / n) + 1e-4)


def test_float_path_has_the_same_distribution():
    """An independent check of the pmf: numpy's float normal draws, rounded, land on it too."""
    n, sigma = 1_000_000, 1.0
    k, p = rounded_gaussian_pmf(sigma)
    y = np.round(sigma * np.random.default_rng(2).standard_normal(n)).astype(np.int64)
    obs, exp = _bins(k, p, np.bincount(y - k[0], minlength=len(k)), n)
    dof = len(obs) - 1
    assert ((obs - exp) ** 2 / exp).sum() < dof + 5 * math.sqrt(2 * dof)


def test_values_are_independent():
    """Neighbours across columns, rows and channels, and two frames of one generator, are uncorrelated."""
    rng = np.random.default_rng(3)
    a = rounded_gaussian((480, 640, 3), 1.0, rng).astype(float)
    b = rounded_gaussian((480, 640, 3), 1.0, rng).astype(float)
    n = a.size
    pairs = [(a[:, 1:], a[:, :-1]), (a[1:], a[:-1]), (a[..., 1:], a[..., :-1]), (a, b),
             (a[:, 1:], b[:, :-1])]
    for u, v in pairs:
        r = np.corrcoef(u.ravel(), v.ravel())[0, 1]
        assert abs(r) < 5 / math.sqrt(n)
    # the sign pattern of runs: P(equal neighbours) matches sum p^2
    k, p = rounded_gaussian_pmf(1.0)
    same = (a[:, 1:] == a[:, :-1]).mean()
    assert same == pytest.approx((p**2).sum(), abs=5 * math.sqrt(0.25 / a[:, 1:].size))


def test_deterministic_and_clipped():
    img = np.random.default_rng(0).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    img[0] = 0
    img[1] = 255
    a = add_rounded_gaussian(img, 2.0, np.random.default_rng([7, 3, 0, 5]))
    b = add_rounded_gaussian(img, 2.0, np.random.default_rng([7, 3, 0, 5]))
    assert a.dtype == np.uint8 and a.shape == img.shape
    assert np.array_equal(a, b)
    k = rounded_gaussian(img.shape, 2.0, np.random.default_rng([7, 3, 0, 5]))  # the same draws
    assert np.array_equal(a, np.clip(img.astype(int) + k, 0, 255))
    assert (a[0] >= 0).all() and (a[1] <= 255).all() and (a[0] > 0).any() and (a[1] < 255).any()
    assert add_rounded_gaussian(img, 0.0, np.random.default_rng(0)) is img


@pytest.mark.parametrize("sigma", [float("nan"), -1.0, 0.0, 2000.0, float("inf")])
def test_bad_sigma_named(sigma):
    with pytest.raises(ValueError, match="sigma"):
        rounded_gaussian((4,), sigma, np.random.default_rng(0))


def test_bad_image_and_rng_named():
    with pytest.raises(TypeError, match="uint8.*shape"):
        add_rounded_gaussian(np.zeros((2, 2), np.float32), 1.0, np.random.default_rng(0))
    with pytest.raises(TypeError, match="Generator"):
        rounded_gaussian((2,), 1.0, 0)
