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


def _views_of(points, cams, sigma=0.9, depth=0.5, noise=0.01, seed=0, shape=(60, 80)):
    """Each camera's image of dark Gaussian spots at the 3-D ``points``."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[:shape[0], :shape[1]]
    out = []
    for cam in cams:
        img = 0.8 + 0.002 * xx + 0.001 * yy
        for c in cam.project(np.asarray(points)):
            img = img - depth * np.exp(-((xx - c[0]) ** 2 + (yy - c[1]) ** 2) / (2 * sigma ** 2))
        out.append(img + rng.normal(0, noise, shape))
    return out


def _low_res_views():
    from lipgen.rig.pinhole import PinholeCamera

    # ~0.8 px per mm at the origin: dots 2.5 mm apart are 1.5-2 px apart in each view, one blob.
    K = np.array([[240.0, 0, 40], [0, 240.0, 30], [0, 0, 1]])
    cams = []
    for deg in (-25.0, 25.0):
        a = np.deg2rad(deg)
        R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
        cams.append(PinholeCamera(K, R, np.array([0, 0, 300.0]), 80, 60))
    return cams


@pytest.mark.parametrize("seed", range(3))
def test_a_pair_merged_in_both_views_is_split_by_one_fit_of_both(seed):
    from lipgen.recon.twins import fit_pair_two_views

    cams = _low_res_views()
    rng = np.random.default_rng(seed)
    mid = rng.uniform(-1, 1, 3)
    half = np.array([0.3, 1.2, 0.4]) + rng.uniform(-0.2, 0.2, 3)          # ~2.6 mm apart
    X = np.array([mid + half, mid - half])
    views = _views_of(X, cams, seed=seed)
    for cam in cams:
        assert np.linalg.norm(np.subtract(*cam.project(X))) < 2.2, "the dots merge in both views"
    # First guesses as the pipeline makes them: the midpoint 0.5 mm off, the separation as in
    # the layout (turned and scaled).
    got = fit_pair_two_views(views, cams, mid + [0.4, -0.3, 0.2], 1.2 * half + [0.2, -0.1, 0.0], 0.9, 1.5)
    assert got is not None
    for cam in cams:
        assert np.linalg.norm(cam.project(got) - cam.project(X), axis=1).max() < 0.15


def test_one_dot_seen_by_both_views_is_not_split_in_two():
    from lipgen.recon.twins import fit_pair_two_views

    cams = _low_res_views()
    views = _views_of(np.zeros((1, 3)), cams)
    assert fit_pair_two_views(views, cams, np.zeros(3), np.array([0.3, 1.2, 0.4]), 0.9, 1.5) is None
