"""The first frame re-posed (:mod:`lipgen.recon.firstpose`, :func:`lipgen.recon.stereo_init.repose_layout`):
a layout far from the subject's pose is moved to where the two views' dots place it."""

import numpy as np
import pytest
from test_raygap import _two_views

from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.stereo_init import repose_layout


def _layout():
    """14 marks on a curved patch (two rows, 6 mm apart), mm."""
    x = np.linspace(-15.0, 15.0, 7)
    return np.array([(xi, y, 0.02 * xi ** 2) for y in (-3.0, 3.0) for xi in x])


def _pose(points, deg, shift):
    a = np.deg2rad(deg)
    R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    return points @ R.T + shift


@pytest.mark.parametrize("deg, shift", [(0.0, (25.0, -12.0, 4.0)), (12.0, (-30.0, 8.0, -6.0))])
def test_a_far_layout_is_re_posed_among_lures(deg, shift):
    """The subject 28-32 mm from the layout's pose, turned 0 or 12 degrees; each view also shows 12
    lures (no partner in the other view) and 4 marks are missing in one view. The re-posed layout
    projects within 0.05 px of the subject's dots; the layout at rest was 50+ px off."""
    cams = _two_views()
    model = _layout()
    subject = _pose(model, deg, np.array(shift))
    rng = np.random.default_rng(3)
    views = []
    for v, cam in enumerate(cams):
        uv = cam.project(subject)
        if v == 0:
            uv = uv[4:]                                   # 4 marks too faint in the mirror
        views.append(np.vstack([uv, rng.uniform([0, 0], [160, 120], (12, 2))]))
    moved = repose_layout(views[0], views[1], cams, model, reach=40.0)
    assert moved is not None
    for cam in cams:
        err = np.linalg.norm(cam.project(moved) - cam.project(subject), axis=1)
        assert err.max() < 0.05
        assert np.linalg.norm(cam.project(model) - cam.project(subject), axis=1).min() > 50


def test_nothing_is_placed_from_too_few_pairs():
    cams = _two_views()
    model = _layout()
    uv = [cam.project(model[:5]) for cam in cams]          # 5 marks in both views: under least = 6
    assert repose_layout(uv[0], uv[1], cams, model) is None
    assert repose_layout(uv[0], uv[1], cams, model, least=5) is not None
    # Farther than the reach plus the layout's span (30 mm), no offset puts any marker on a point
    far = [cam.project(model + [75.0, 0, 0]) for cam in cams]
    assert repose_layout(far[0], far[1], cams, model, reach=40.0) is None


@pytest.mark.parametrize("bad", [0, -1, 2.5, True, "6"])
def test_the_setting_is_checked(bad):
    with pytest.raises(ValueError, match="first_frame_repose"):
        ReconstructSettings(first_frame_repose=bad)
