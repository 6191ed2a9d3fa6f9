"""The model of two merged dots (lipgen.recon.twins) on synthetic images with known centres."""

import numpy as np
import pytest

from lipgen.recon.twins import fit_pair


def _two_dots(centres, sigma=1.1, depth=0.5, noise=0.01, seed=0, shape=(40, 40)):
    """Two dark Gaussian spots on a bright, slightly sloped background, with sensor noise."""
    yy, xx = np.mgrid[:shape[0], :shape[1]]
    img = 0.8 + 0.002 * xx
    for c in centres:
        img = img - depth * np.exp(-((xx - c[0]) ** 2 + (yy - c[1]) ** 2) / (2 * sigma ** 2))
    return img + np.random.default_rng(seed).normal(0, noise, shape)


@pytest.mark.parametrize("seed", range(4))
def test_two_merged_dots_are_found_on_their_lines(seed):
    rng = np.random.default_rng(seed)
    a = np.array([20.0, 20.0]) + rng.uniform(-0.5, 0.5, 2)
    b = a + np.array([0.6, 2.2])                           # 2.3 px apart: one blob
    img = _two_dots([a, b], seed=seed)
    # each centre lies on its own line (as on its epipolar line), nearly parallel to the other's
    d = np.array([1.0, 0.15]) / np.hypot(1.0, 0.15)
    lines = [(a - 3 * d, d), (b + 2 * d, d)]
    init = np.array([a + 1.2 * d, b - 1.0 * d])               # off by 1 px along the lines
    got = fit_pair(img, lines, init, sigma0=1.3, gate=3.0)
    assert got is not None
    assert np.linalg.norm(got - np.array([a, b]), axis=1).max() < 0.15


def test_a_single_dot_is_not_split_in_two():
    a = np.array([20.0, 20.0])
    img = _two_dots([a])
    d = np.array([1.0, 0.0])
    got = fit_pair(img, [(a, d), (a + [0.0, 2.5], d)], np.array([a, a + [0.0, 2.5]]), sigma0=1.3, gate=3.0)
    assert got is None, "no second dot: the fit must not invent one"


def test_a_pair_at_the_image_edge_is_not_fitted():
    img = _two_dots([[2.0, 20.0], [3.0, 22.0]])
    d = np.array([0.0, 1.0])
    assert fit_pair(img, [(np.array([2.0, 20.0]), d), (np.array([3.0, 22.0]), d)],
                    np.array([[2.0, 20.0], [3.0, 22.0]]), 1.3, 3.0) is None
