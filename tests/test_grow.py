"""The first frame grown from a few markers matched in both views (:mod:`lipgen.recon.grow`)."""

import numpy as np
import pytest
from test_firstframe import _layout, _lure_on_epipolar_line, _views
from test_raygap import _two_views

from lipgen.recon.grow import grow_first_frame, place_layout_3d
from lipgen.rig.pinhole import triangulate


def _subject(seed=0):
    """The layout turned 8 degrees, moved, the lower row 1.5 mm down (the mouth opening), 0.1 mm noise."""
    model = _layout()
    a = np.deg2rad(8)
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    truth = model @ R.T + [1.5, -2.0, 4.0]
    truth[model[:, 1] < 0, 1] -= 1.5
    return model, truth + np.random.default_rng(seed).normal(0, 0.1, model.shape)


def test_place_layout_3d_is_exact_for_a_moved_layout_and_checks_the_seeds():
    model = _layout()
    a = np.deg2rad(12)
    R = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    moved = model @ R.T + [3.0, 1.0, -2.0]
    for seeds in ([0, 6, 10], [0, 3, 6, 7, 12]):
        use = np.zeros(len(model), dtype=bool)
        use[seeds] = True
        np.testing.assert_allclose(place_layout_3d(model, moved, use, width=5.0), moved, atol=1e-9)
    with pytest.raises(ValueError, match="seeds"):
        place_layout_3d(model, moved, np.arange(len(model)) < 2, width=5.0)


def test_a_view_with_three_confident_matches_grows_to_all_markers():
    cams = _two_views()
    model, truth = _subject()
    uv = _views(truth, cams)
    rng = np.random.default_rng(3)
    # Both views' dots in a shuffled order, and view 0 (the mirror) matched only 3 markers.
    dots = [u[rng.permutation(len(u))] for u in uv]
    inits = [np.full_like(uv[0], np.nan), uv[1].copy()]
    seeds = [0, 4, 9]
    inits[0][seeds] = uv[0][seeds]
    out, grown = grow_first_frame(inits, dots, cams, model, max_gap=0.5)
    np.testing.assert_allclose(out[0], uv[0], atol=1e-9)
    np.testing.assert_array_equal(out[1], uv[1])
    expect = np.ones(len(model), dtype=bool)
    expect[seeds] = False
    np.testing.assert_array_equal(grown[0], expect)
    assert not grown[1].any()
    # Neither view matched the markers but the seeds: they grow from free pairs of dots.
    inits = [np.full_like(uv[0], np.nan), np.full_like(uv[1], np.nan)]
    for v in range(2):
        inits[v][seeds] = uv[v][seeds]
    out, grown = grow_first_frame(inits, dots, cams, model, max_gap=0.5)
    for v in range(2):
        np.testing.assert_allclose(out[v], uv[v], atol=1e-9)


@pytest.mark.parametrize("own_dot_found", [True, False])
def test_a_lure_on_the_epipolar_line_is_not_taken(own_dot_found):
    cams = _two_views()
    model, truth = _subject(1)
    uv = _views(truth, cams)
    bad = 11
    # On view 1's dot's line, in view 0: beside its own dot 3 mm along the ray; alone, 6 mm along
    # (beyond ``near``, 0.8 of the 5 mm spacing).
    along = 3.0 if own_dot_found else 6.0
    lure = _lure_on_epipolar_line([cams[1], cams[0]], truth[bad], along)
    gap = triangulate(cams[1], uv[1][bad][None], cams[0], lure[None])[1]
    assert gap[0] < 1e-6 and np.linalg.norm(lure - uv[0][bad]) > 2.0
    dots = [np.vstack([uv[0], lure[None]]), uv[1].copy()]
    if not own_dot_found:
        dots[0] = np.delete(dots[0], bad, axis=0)
    inits = [np.full_like(uv[0], np.nan), uv[1].copy()]
    inits[0][[0, 4, 9]] = uv[0][[0, 4, 9]]
    out, grown = grow_first_frame(inits, dots, cams, model, max_gap=0.5)
    if own_dot_found:
        np.testing.assert_allclose(out[0][bad], uv[0][bad], atol=1e-9)
    else:
        assert np.all(np.isnan(out[0][bad])), "the lure is 6 mm along the ray from the prediction"
    keep = np.arange(len(model)) != bad
    np.testing.assert_allclose(out[0][keep], uv[0][keep], atol=1e-9)


def test_a_wrong_single_view_match_is_replaced_and_a_right_one_kept():
    cams = _two_views()
    model, truth = _subject(2)
    uv = _views(truth, cams)
    inits = [np.full_like(uv[0], np.nan), uv[1].copy()]
    inits[0][[0, 4, 9]] = uv[0][[0, 4, 9]]
    inits[1][12] = uv[1][13]            # view 1 matched marker 12 to marker 13's dot
    inits[1][13] = np.nan
    out, _ = grow_first_frame(inits, uv, cams, model, max_gap=0.5)
    for v in range(2):
        np.testing.assert_allclose(out[v], uv[v], atol=1e-9)


def test_too_few_seeds_change_nothing():
    cams = _two_views()
    model, truth = _subject()
    uv = _views(truth, cams)
    inits = [np.full_like(uv[0], np.nan), uv[1].copy()]
    inits[0][[0, 4]] = uv[0][[0, 4]]
    out, grown = grow_first_frame(inits, uv, cams, model, max_gap=0.5)
    assert not grown.any()
    np.testing.assert_array_equal(out[0], inits[0])
    with pytest.raises(ValueError, match="min_seeds"):
        grow_first_frame(inits, uv, cams, model, max_gap=0.5, min_seeds=2)
