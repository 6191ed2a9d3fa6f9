"""The tracker's rules for hard-preset frames: the windowed dot fit and the first frame's lures.

Each CI test is a small synthetic case with a known answer; the hard-preset figures are in the
slow test at the end (validation seeds; the closing note gives test seeds).
"""

import numpy as np
import pytest
from synthetic_images import draw_dots

from lipgen.recon.dots import refine_centroids
from lipgen.recon.stereo_init import layout_dots, stereo_candidates
from lipgen.rig.pinhole import PinholeCamera


def _dot_beside_an_edge(rng, offset, sigma=1.3, gap=3.5):
    """A dot at a known sub-pixel place with a dark step (the mouth opening) ``gap`` px below it."""
    img = np.full((40, 40), 0.7)
    c = np.array([20.0, 18.0]) + offset
    img[int(np.ceil(c[1] + gap)):, :] = 0.15          # the dark slit, a step no quadratic follows
    img = draw_dots(img, c[None], sigma=sigma, depth=0.35)
    return img + 0.005 * rng.standard_normal(img.shape), c


@pytest.mark.parametrize("gap, most", [(4.5, 0.15), (3.5, 0.4)])
def test_windowed_fit_is_not_pulled_by_a_dark_step_beside_the_dot(gap, most):
    # A dot ``gap`` px above a dark step (the mouth opening next to a lip dot). Without the window
    # the quadratic background cannot follow the step and the centre is pulled toward it by about
    # 0.7 px; the window keeps it within ``most`` (under 0.1 px on average 4.5 px from the step).
    # Starts are the rounded centres, as a detector gives them.
    rng = np.random.default_rng(3)
    err_window, err_plain = [], []
    for _ in range(12):
        img, c = _dot_beside_an_edge(rng, rng.uniform(-0.5, 0.5, 2), gap=gap)
        start = np.round(c)[None]
        err_window.append(np.linalg.norm(refine_centroids(img, start, 1.3, window=1.25)[0] - c))
        err_plain.append(np.linalg.norm(refine_centroids(img, start, 1.3, window=None)[0] - c))
    assert max(err_window) < most
    assert np.mean(err_plain) > 0.5
    assert np.mean(err_plain) > 2.5 * np.mean(err_window)


def test_windowed_fit_is_unbiased_on_a_plain_dot():
    # Nothing beside the dot: the window changes nothing but the noise (closed form: the centre).
    rng = np.random.default_rng(4)
    c = rng.uniform(15, 25, (10, 2))
    img = draw_dots(np.full((40, 40), 0.6), c[:1], sigma=1.5) + 0.003 * rng.standard_normal((40, 40))
    assert np.linalg.norm(refine_centroids(img, np.round(c[:1]), 1.5, window=1.25)[0] - c[0]) < 0.05


def test_window_must_be_positive():
    with pytest.raises(ValueError, match="window"):
        refine_centroids(np.zeros((20, 20)), np.array([[10.0, 10.0]]), 1.5, window=0.0)


def _rig():
    K = np.array([[800.0, 0, 160], [0, 800.0, 120], [0, 0, 1]])
    a = np.deg2rad(25)
    Ry = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    return (PinholeCamera(K, Ry, np.array([0, 0, 300.0]), 320, 240),
            PinholeCamera(K, np.eye(3), np.array([0, 0, 300.0]), 320, 240))


def test_stereo_candidates_pair_dots_whose_rays_meet():
    cams = _rig()
    X = np.array([[0.0, 0, 0], [10, 2, 1], [-8, -3, 2]])
    dv, dr = cams[0].project(X), cams[1].project(X)
    pts, pairs = stereo_candidates(dv, dr[::-1], cams, max_gap=0.2)
    right = {(0, 2), (1, 1), (2, 0)}
    assert right <= {tuple(p) for p in pairs}
    for (i, j), p in zip(pairs, pts, strict=True):
        if (i, j) in right:
            assert np.allclose(p, X[i], atol=1e-6)


def test_layout_dots_drop_a_shadow_and_a_tooth_gap_but_keep_the_marked_dots():
    # Ten marks on a lip-like arc, seen in both views, the whole layout shifted by (3, -2, 1) mm
    # and each mark moved by up to 1 mm (the subject's own shape). Two lures: a blob in one view
    # only (a shadow: no partner) and a dark gap 12 mm behind the lips (seen in both views, far
    # from every mark). The marks are kept in both views, the lures dropped.
    rng = np.random.default_rng(8)
    ang = np.linspace(-1.0, 1.0, 10)
    layout = np.column_stack([25 * np.sin(ang), 6 * np.sign(np.arange(10) % 2 - 0.5), 8 * np.cos(ang)])
    marks = layout + np.array([3.0, -2.0, 1.0]) + rng.uniform(-1, 1, layout.shape)
    cams = _rig()
    gap = np.array([[0.0, 0.0, -12.0]])
    dv = np.vstack([cams[0].project(marks), cams[0].project(gap), [[150.0, 60.0]]])
    dr = np.vstack([cams[1].project(marks), cams[1].project(gap)])
    keep_v, keep_r = layout_dots(dv, dr, cams, layout)
    assert keep_v[:10].all() and keep_r[:10].all()
    assert not keep_v[10] and not keep_r[10]       # the gap behind the lips
    assert not keep_v[11]                           # the shadow


def test_layout_dots_keep_everything_when_nothing_can_be_placed():
    cams = _rig()
    keep_v, keep_r = layout_dots(np.array([[10.0, 10.0]]), np.array([[200.0, 30.0]]), cams,
                                 np.zeros((5, 3)))
    assert keep_v.all() and keep_r.all()
