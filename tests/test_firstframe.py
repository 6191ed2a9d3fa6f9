"""The first frame's matches: faint lures are not matched, and a lure on the epipolar line is found
in 3-D (:mod:`lipgen.recon.firstframe`)."""

import numpy as np
import pytest
from test_raygap import _two_views

from lipgen.recon.firstframe import check_layout, match_first_frame, predict_layout
from lipgen.rig.pinhole import triangulate


def _layout():
    """14 marks on a curved patch (two rows, 6 mm apart), mm, in front of the two views."""
    x = np.linspace(-15.0, 15.0, 7)
    pts = [(xi, y, 0.02 * xi ** 2) for y in (-3.0, 3.0) for xi in x]
    return np.array(pts)


def _views(points, cams):
    return [c.project(points) for c in cams]


def _lure_on_epipolar_line(cams, point, along_mm):
    """The view-1 pixel of a point moved ``along_mm`` along view 0's ray through ``point``."""
    ray = point - cams[0].center
    ray /= np.linalg.norm(ray)
    return cams[1].project((point + along_mm * ray)[None])[0]


def test_predict_layout_is_exact_for_a_moved_layout():
    model = _layout()
    a = np.deg2rad(10)
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    moved = model @ R.T + [2.0, -1.0, 5.0]
    pred = predict_layout(model, moved, np.ones(len(model), dtype=bool), width=5.0)
    np.testing.assert_allclose(pred, moved, atol=1e-9)


@pytest.mark.parametrize("own_dot_found", [True, False])
def test_a_lure_on_the_epipolar_line_is_refused(own_dot_found):
    cams = _two_views()
    model = _layout()
    rng = np.random.default_rng(0)
    truth = model + [1.0, 0.5, 3.0] + rng.normal(0, 0.1, model.shape)   # the subject, moved
    uv = _views(truth, cams)
    bad = 3
    lure = _lure_on_epipolar_line(cams, truth[bad], 4.0)
    # the lure's ray meets view 0's ray of the right dot: the ray-gap test cannot see it
    gap = triangulate(cams[1], lure[None], cams[0], uv[0][bad][None])[1]
    assert gap[0] < 1e-6 and np.linalg.norm(lure - uv[1][bad]) > 3.0
    inits = [uv[0].copy(), uv[1].copy()]
    inits[1][bad] = lure
    dots = [uv[0].copy(), np.vstack([uv[1], lure[None]])]
    if not own_dot_found:
        dots[1] = np.delete(dots[1], bad, axis=0)
    out, changed = check_layout(inits, dots, cams, model, max_gap=1.0)
    assert changed[1, bad] and not changed[0].any()
    assert np.count_nonzero(changed) == 1, "no other match is touched"
    np.testing.assert_allclose(out[0], uv[0])
    if own_dot_found:
        np.testing.assert_allclose(out[1][bad], uv[1][bad], atol=1e-9)
    else:
        assert np.all(np.isnan(out[1][bad])), "left to the tracker to acquire later"
    keep = np.arange(len(model)) != bad
    np.testing.assert_allclose(out[1][keep], uv[1][keep])


def test_a_right_first_frame_is_left_alone():
    cams = _two_views()
    model = _layout()
    rng = np.random.default_rng(1)
    truth = model + rng.normal(0, 0.3, model.shape)     # the subject's own dots, 0.3 mm off the model
    uv = _views(truth, cams)
    inits = [u + rng.normal(0, 0.1, u.shape) for u in uv]
    inits[0][5] = np.nan                                  # one view did not match a marker
    out, changed = check_layout(inits, uv, cams, model, max_gap=1.0)
    assert not changed.any()
    for v in range(2):
        np.testing.assert_array_equal(out[v], inits[v])


def test_too_few_matches_in_both_views_are_not_checked():
    cams = _two_views()
    model = _layout()
    uv = _views(model, cams)
    inits = [uv[0].copy(), np.full_like(uv[1], np.nan)]
    inits[1][:5] = uv[1][:5] + [0.0, 4.0]
    out, changed = check_layout(inits, uv, cams, model, max_gap=1.0)
    assert not changed.any()


def test_a_faint_lure_beside_the_layout_position_is_not_matched():
    # 3 x 5 grid 10 px apart; marker 7's dot is 4 px right of where the layout puts it, and a
    # faint blob (a quarter as dark) sits on the layout position.
    expected = np.array([(40.0 + 10 * i, 50.0 + 10 * j) for j in range(3) for i in range(5)])
    dots = expected.copy()
    dots[7] += [4.0, 0.0]
    dots = np.vstack([dots, expected[7][None]])
    strength = np.r_[np.full(15, 0.4), 0.1]
    plain = match_first_frame(dots, strength, expected, gate=6.0, dark=None)
    assert plain[7] != 7, "without the darkness the lure wins or the match is ambiguous"
    got = match_first_frame(dots, strength, expected, gate=6.0, dark=0.4)
    assert got[7] == 7
    np.testing.assert_array_equal(np.delete(got, 7), np.delete(np.arange(15), 7))
    with pytest.raises(ValueError, match="strength"):
        match_first_frame(dots, strength[:3], expected, gate=6.0)
