"""Dots the detector cannot find alone (lipgen.recon.blend): merged neighbours.

Synthetic frames with known centres (tests/synthetic_images.py): blurred dots drawn as Gaussians
on a textured, shaded background with pixel noise.
"""

import numpy as np
import pytest
from synthetic_images import background, draw_dots

from lipgen.recon.blend import fit_blend
from lipgen.recon.dots import DotSettings, detect_dots
from lipgen.recon.track import MarkerTracker, TrackerSettings

SHAPE = (60, 80)


def _image(base, uv, rng, sigma, depth, noise=0.005):
    img = draw_dots(base, np.asarray(uv, float), sigma=sigma, depth=depth)
    return img + noise * rng.standard_normal(SHAPE)


@pytest.mark.parametrize("seed", range(3))
def test_two_blurred_dots_4px_apart_are_both_fitted_from_rough_starts(seed):
    rng = np.random.default_rng(seed)
    base = background(SHAPE, rng, texture=0.03)
    c = np.array([40.0, 30.0]) + rng.uniform(-0.5, 0.5, 2)
    a = rng.uniform(0, np.pi)
    half = 2.0 * np.array([np.cos(a), np.sin(a)])
    truth = np.array([c - half, c + half])
    img = _image(base, truth, rng, sigma=1.6, depth=0.3)
    fit = fit_blend(img, truth + rng.uniform(-1.0, 1.0, truth.shape), 1.3, 3.0)
    assert fit is not None and fit.ok
    assert np.linalg.norm(fit.uv - truth, axis=1).max() < 0.3


def test_one_dot_is_not_split_in_two():
    rng = np.random.default_rng(5)
    base = background(SHAPE, rng, texture=0.03)
    img = _image(base, [[40.0, 30.0]], rng, sigma=1.6, depth=0.3)
    fit = fit_blend(img, np.array([[38.5, 30.0], [41.5, 30.0]]), 1.3, 3.0)
    assert fit is not None and not fit.ok


def test_bad_starts_are_refused():
    with pytest.raises(ValueError, match="starts"):
        fit_blend(np.zeros(SHAPE), np.zeros((2, 3)), 1.3, 3.0)
    with pytest.raises(ValueError, match="reach"):
        fit_blend(np.zeros(SHAPE), np.zeros((2, 2)) + 30, 1.3, [3.0, -1.0])


def _two_markers(gap_px, n_frames=8):
    """Two markers drifting right, their spacing shrinking from 9 px to ``gap_px``."""
    t = np.linspace(0.0, 1.0, n_frames)[:, None]
    mid = np.array([34.0, 30.0]) + t * np.array([6.0, 1.0])
    half = (4.5 + t * (gap_px / 2 - 4.5)) * np.array([1.0, 0.3]) / np.hypot(1.0, 0.3)
    return np.stack([mid - half, mid + half], axis=1)             # (F, 2, 2)


@pytest.mark.parametrize("seed", range(2))
def test_the_tracker_keeps_both_of_two_blurred_dots_4px_apart(seed):
    rng = np.random.default_rng(seed)
    base = background(SHAPE, rng, texture=0.03)
    paths = _two_markers(4.0)
    frames = [_image(base, p, rng, sigma=1.6, depth=0.3) for p in paths]
    cfg = TrackerSettings(dots=DotSettings(sigma=1.3))
    assert len(detect_dots(frames[-1], cfg.dots)[0]) < 2

    def run(settings):
        tr = MarkerTracker(paths[0], settings)
        for f in frames:
            tr.step(f)
        return tr.tracks()

    got = run(cfg)
    assert got.visible.all()
    assert np.linalg.norm(got.uv - paths, axis=2).max() < 0.3
    without = run(TrackerSettings(dots=cfg.dots, blend=False, blobs=False))   # (the blobs keep it too)
    assert not without.visible[-1].all(), "without the joint fit the merged pair is lost"
