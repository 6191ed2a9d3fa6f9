"""A lost marker fitted as a dark spot on the other view's epipolar line (lipgen.recon.linefit)."""

import numpy as np
import pytest
from scipy import ndimage
from synthetic_images import background, draw_dots, frame
from test_raygap import _two_views

from lipgen.recon.dots import DotSettings, detect_dots
from lipgen.recon.linefit import fit_spot_on_line, recover_by_line_fit
from lipgen.recon.raygap import RayGapLimit, px_per_mm
from lipgen.recon.track import MarkerTracker, TrackerSettings
from lipgen.recon.viewcheck import check_views


def _ink_dot(shape, centre, radius, rng, blur, harmonics=(2, 3, 4), amplitude=0.08, ss=4):
    """A disc of ink with a wavy rim (radius times 1 + sum a_k cos(k phi + phase_k)), supersampled
    ``ss`` times, blurred by ``blur`` px (defocus). Returns its coverage (h, w) in [0, 1] and the
    ink's true centroid (2,) (x, y)."""
    h, w = shape
    yy, xx = np.mgrid[:h * ss, :w * ss]
    x, y = (xx + 0.5) / ss - 0.5 - centre[0], (yy + 0.5) / ss - 0.5 - centre[1]
    phi, rho = np.arctan2(y, x), np.hypot(x, y)
    rim = radius * (1 + sum(amplitude * np.cos(k * phi + rng.uniform(0, 2 * np.pi)) for k in harmonics))
    ink = (rho <= rim).astype(float)
    cov = ink.reshape(h, ss, w, ss).mean(axis=(1, 3))
    centroid = np.array([(x[ink > 0] + centre[0]).mean(), (y[ink > 0] + centre[1]).mean()])
    return ndimage.gaussian_filter(cov, blur), centroid


@pytest.mark.parametrize("seed", range(3))
def test_a_blurred_irregular_dot_merged_with_a_neighbour_is_found_on_its_line(seed):
    rng = np.random.default_rng(seed)
    shape = (48, 48)
    c = np.array([24.0, 24.0]) + rng.uniform(-0.5, 0.5, 2)
    nb = c + np.array([3.2, 2.0])                      # 3.8 px away: one blob after the blur
    ink, truth = _ink_dot(shape, c, 1.6, rng, blur=1.2)
    ink_nb, truth_nb = _ink_dot(shape, nb, 1.6, rng, blur=1.2)
    yy, xx = np.mgrid[:shape[0], :shape[1]]
    img = 0.75 + 0.003 * xx - 0.002 * yy - 0.45 * ink - 0.45 * ink_nb
    img += rng.normal(0, 0.01, shape)
    d = np.array([1.0, 0.3]) / np.hypot(1.0, 0.3)
    got = fit_spot_on_line(img, truth - 5 * d, d, truth + 2.0 * d + [0.0, 1.0], 1.3, 4.0, truth_nb[None])
    assert got is not None
    centre, depth, radius = got
    assert np.linalg.norm(centre - truth) < 0.25
    assert depth > 0.1 and 0.65 < radius < 3.9


def test_a_specular_highlight_is_not_a_dot():
    rng = np.random.default_rng(5)
    shape = (48, 48)
    c = np.array([24.3, 23.6])
    yy, xx = np.mgrid[:shape[0], :shape[1]]
    img = 0.6 + 0.35 * np.exp(-((xx - c[0]) ** 2 + (yy - c[1]) ** 2) / (2 * 1.5 ** 2))  # a bright glint
    img += rng.normal(0, 0.01, shape)
    d = np.array([1.0, 0.0])
    got = fit_spot_on_line(img, c - 5 * d, d, c, 1.3, 4.0)
    assert got is None or got[1] < 0.02, "a bright spot has no dark depth"
    assert len(detect_dots(img, DotSettings(sigma=1.3))[0]) == 0
    # A dark dot beside the glint is still found, at its centre.
    dark = draw_dots(img, np.array([[34.0, 24.0]]), sigma=1.3, depth=0.3)
    found, _ = detect_dots(dark, DotSettings(sigma=1.3))
    assert len(found) == 1 and np.linalg.norm(found[0] - [34.0, 24.0]) < 0.15


def test_bad_inputs_are_named():
    img = np.full((30, 30), 0.7)
    with pytest.raises(ValueError, match="unit length"):
        fit_spot_on_line(img, [0.0, 0.0], [2.0, 0.0], [15.0, 15.0], 1.3, 3.0)
    with pytest.raises(ValueError, match="strength_ratio"):
        recover_by_line_fit([], [], None, 1.0, strength_ratio=0.8, max_ratio=0.5)
    assert fit_spot_on_line(img, [0.0, 1.0], [1.0, 0.0], [1.0, 1.0], 1.3, 3.0) is None   # off the image


def _run(fit: bool, hide: bool, seed: int = 3, n_frames: int = 14):
    """Track 6 marks in two views; from frame 4 mark 0's dot in view 0 is pale and blurred
    (``hide``: gone). Returns (tracks per view, true uv (2, F, P, 2))."""
    cams = _two_views()
    rng = np.random.default_rng(seed)
    grid = np.array([(x, y, 0.0) for y in (-6.0, 6.0) for x in (-8.0, 0.0, 8.0)])
    t = np.arange(n_frames)[:, None, None]
    marks = grid[None] + np.array([1.5, 1.0, 2.0]) * np.sin(0.3 * t)
    uv = np.stack([np.stack([c.project(m) for m in marks]) for c in cams])
    bases = [background((120, 160), rng, texture=0.03) for _ in cams]
    settings = TrackerSettings(dots=DotSettings(sigma=1.5), confident_correlation=1.0)
    trackers = [MarkerTracker(uv[v, 0], settings) for v in range(2)]
    limit = RayGapLimit(2.0, k=8.0, floor=1.0 / px_per_mm(cams), min_samples=30)
    for f in range(n_frames):
        images = []
        for v in range(2):
            pale = (v == 0) & (f >= 4)
            img = draw_dots(bases[v], uv[v, f][1:] if pale else uv[v, f], depth=0.13)
            if pale and not hide:
                img = draw_dots(img, uv[v, f][:1], sigma=2.2, depth=0.065)
            images.append(frame(img, np.zeros((0, 2)), rng, noise=0.003))
        for v in range(2):
            trackers[v].step(images[v])
        if f > 0:
            if fit:
                recover_by_line_fit(trackers, images, cams, limit.limit())
            check_views(trackers, cams, limit)
    return [tr.tracks() for tr in trackers], uv


def test_a_pale_blurred_dot_is_followed_and_a_hidden_one_is_not_invented():
    off, uv = _run(fit=False, hide=False)
    assert off[0].visible[4:, 0].mean() <= 0.6, "the tracker alone loses the pale dot in most frames"
    on, _ = _run(fit=True, hide=False)
    vis = on[0].visible[4:, 0]
    assert vis.mean() >= 0.8
    err = np.linalg.norm(on[0].uv[4:, 0] - uv[0, 4:, 0], axis=1)[vis]
    assert err.max() < 0.75 and np.sqrt(np.mean(err ** 2)) < 0.5   # a pale blurred dot on texture
    hidden, _ = _run(fit=True, hide=True)
    assert hidden[0].visible[4:, 0].sum() == 0, "no dot there: nothing may be taken"
