"""The first frame seeded from one view when the views' matches agree on too few markers
(:mod:`lipgen.recon.seedview`, ``check_first_frame(one_view=...)``)."""

import numpy as np
import pytest
from test_firstframe import _layout, _views
from test_grow import _subject
from test_raygap import _two_views

from lipgen.recon.grow import check_first_frame
from lipgen.recon.seedview import place_on_rays, seed_from_one_view


def _turned(model, degrees, axis=1):
    a = np.deg2rad(degrees)
    c, s = np.cos(a), np.sin(a)
    R = {0: [[1, 0, 0], [0, c, -s], [0, s, c]], 1: [[c, 0, s], [0, 1, 0], [-s, 0, c]],
         2: [[c, -s, 0], [s, c, 0], [0, 0, 1]]}[axis]
    return model @ np.array(R).T


def _failed_registration(wrong_view, seed=0, shift=(0.0, 12.0)):
    """The subject's dots in both views; ``wrong_view`` matched every marker to a lure ``shift`` px
    from its dot (across the epipolar lines, which run along the rows), as a 2-D registration on
    the teeth does. Returns (cams, model, uv, dots, inits)."""
    cams = _two_views()
    model, truth = _subject(seed)
    uv = _views(truth, cams)
    lures = uv[wrong_view] + np.asarray(shift)
    dots = [u.copy() for u in uv]
    dots[wrong_view] = np.vstack([uv[wrong_view], lures])
    inits = [u.copy() for u in uv]
    inits[wrong_view] = lures.copy()
    return cams, model, uv, dots, inits


def test_place_on_rays_recovers_a_rigidly_moved_layout_from_one_view():
    cams = _two_views()
    model = _layout()
    truth = _turned(model, 6.0, axis=0) + [2.0, -1.5, 3.0]
    for v in range(2):
        placed, dist, used, turn = place_on_rays(cams[v], cams[v].project(truth), model)
        np.testing.assert_allclose(placed, truth, atol=1e-4)
        assert dist.max() < 1e-5 and used.all() and turn == pytest.approx(6.0, abs=1e-3)
    with pytest.raises(ValueError, match="at least 4 markers"):
        place_on_rays(cams[0], cams[0].project(truth[:3]), model[:3])


@pytest.mark.parametrize("wrong_view", [0, 1])
def test_a_view_registered_on_lures_no_longer_drops_the_other_views_right_matches(wrong_view):
    cams, model, uv, dots, inits = _failed_registration(wrong_view)
    # Main's behaviour: every pair's rays miss, all are dropped in both views, nothing grows.
    out, bad = check_first_frame(inits, dots, cams, 0.5, model)
    assert bad.all()
    assert all(np.isnan(u).all() for u in out)
    # Seeded from the right view: every marker matched right in both views.
    out, bad = check_first_frame(inits, dots, cams, 0.5, model, one_view=3)
    assert not bad.any()
    for v in range(2):
        np.testing.assert_allclose(out[v], uv[v], atol=1e-9)
    seeded, view = seed_from_one_view(inits, dots, cams, model, 0.5)
    assert view == 1 - wrong_view
    np.testing.assert_array_equal(seeded[1 - wrong_view], inits[1 - wrong_view])


def test_enough_pairs_left_or_no_view_confirmed_change_nothing():
    cams, model, uv, dots, inits = _failed_registration(0)
    # 4 pairs left right in both views: with one_view=4 nothing acts, the result is main's to the bit.
    right = [0, 3, 7, 10]
    inits[0][right] = uv[0][right]
    base = check_first_frame(inits, dots, cams, 0.5, model)
    for n in (None, 3, 4):
        out, bad = check_first_frame(inits, dots, cams, 0.5, model, one_view=n)
        np.testing.assert_array_equal(bad, base[1])
        for v in range(2):
            np.testing.assert_array_equal(out[v], base[0][v])
    # Both views on lures that no dot of the other view confirms: main's result stands.
    lone = [uv[0] - [0.0, 12.0], uv[1] + [0.0, 12.0]]
    dots = [np.vstack([uv[v], lone[v]]) for v in range(2)]
    assert seed_from_one_view(lone, dots, cams, model, 0.5)[1] is None
    base = check_first_frame(lone, dots, cams, 0.5, model)
    out, bad = check_first_frame(lone, dots, cams, 0.5, model, one_view=3)
    for v in range(2):
        np.testing.assert_array_equal(out[v], base[0][v])


def test_a_registration_turned_beyond_max_turn_is_not_a_seed_view():
    cams = _two_views()
    model, truth = _subject(3)
    # A thing with the layout's shape turned 40 degrees about the view axis, its dots in both views
    # (so each view confirms the other's): no lip layout turns so on the rig; view 1 matched it.
    far = _turned(truth - truth.mean(0), 40.0, axis=2) + truth.mean(0)
    dots = [cams[0].project(far), cams[1].project(far)]
    inits = [np.full_like(dots[0], np.nan), dots[1].copy()]
    seeded, view = seed_from_one_view(inits, dots, cams, model, 0.5, max_turn=90.0)
    assert view == 1 and np.isfinite(seeded[0]).all(), "turned freely, it is a layout both views confirm"
    assert seed_from_one_view(inits, dots, cams, model, 0.5)[1] is None


def test_the_setting_is_checked_and_reaches_the_first_frame(monkeypatch):
    from test_shifted import _two_view_frames

    import lipgen.recon.firstpose as firstpose
    import lipgen.recon.steps as steps
    from lipgen.recon.settings import ReconstructSettings

    for bad in (0, -1, 2.5, True, "3"):
        with pytest.raises(ValueError, match="first_frame_one_view"):
            ReconstructSettings(first_frame_one_view=bad)
    raws, layout, expected, cams, X = _two_view_frames(1)
    seen = []
    real = firstpose.check_first_frame      # called for track_raw_frames by lipgen.recon.firstpose
    monkeypatch.setattr(firstpose, "check_first_frame", lambda *a: seen.append(a[-1]) or real(*a))
    for n in (None, 6):
        steps.track_raw_frames(iter(raws), layout, expected, ReconstructSettings(first_frame_one_view=n),
                               cameras=cams, rest_points=X)
    assert seen == [None, 6]


def test_a_seeding_that_moves_a_pair_whose_rays_met_is_not_taken():
    from lipgen.recon.seedview import moves_pairs

    u = [np.array([[0.0, 0.0], [10.0, 0.0], [np.nan, np.nan]]),
         np.array([[1.0, 1.0], [11.0, 1.0], [20.0, 1.0]])]
    pairs = np.array([True, True, False])
    assert not moves_pairs(u, u, pairs)
    same_plus = [np.array([[0.0, 0.0], [np.nan, np.nan], [30.0, 0.0]]), u[1]]
    assert not moves_pairs(same_plus, u, pairs), "a pair left unmatched or a new marker moves nothing"
    moved = [np.array([[0.0, 0.0], [12.0, 0.0], [np.nan, np.nan]]), u[1]]
    assert moves_pairs(moved, u, pairs), "marker 1 on another dot"
    given = [np.array([[0.0, 0.0], [np.nan, np.nan], [10.0, 0.0]]), u[1]]
    assert moves_pairs(given, u, pairs), "marker 1's dot given to marker 2"
    # In the first frame: view 0 registered on lures, but one wrong pair's rays met (a lure on the
    # epipolar line of view 1's dot). The seeding from view 1 would move it: it is not taken.
    cams, model, uv, dots, inits = _failed_registration(0)
    k = 5
    o, d = cams[1].rays(uv[1][k][None])  # on view 1's ray of marker k's dot, 4 mm nearer the camera
    t = np.linalg.norm(_subject(0)[1][k] - o[0]) - 4.0
    lure = cams[0].project((o[0] + t * d[0] / np.linalg.norm(d[0]))[None])[0]
    inits[0][k] = lure
    dots[0] = np.vstack([dots[0], lure[None]])
    base = check_first_frame(inits, dots, cams, 0.5, model)
    assert np.isfinite(base[0][0][k]).all(), "the lure's pair survives the ray-gap check"
    out, _ = check_first_frame(inits, dots, cams, 0.5, model, one_view=3)
    for v in range(2):
        np.testing.assert_array_equal(out[v], base[0][v])


def test_seeds_the_growth_cannot_extend_are_not_taken():
    """``hard`` 48: the direct view matched right, the mirror's markers' dots were not found, and 3
    lures met the direct view's rays where a layout moved in depth puts 3 markers. The 3 wrong
    seeds grew to nothing; right seeds grow (the test above: all 17)."""
    cams = _two_views()
    model, truth = _subject(0)
    uv = _views(truth, cams)
    o, d = cams[1].rays(uv[1])
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    k = [0, 1, 7]
    lures = cams[0].project(truth[k] + 8.0 * d[k])   # on view 1's rays, 8 mm deeper
    dots = [lures, uv[1].copy()]
    inits = [np.full_like(uv[0], np.nan), uv[1].copy()]
    seeded, view = seed_from_one_view(inits, dots, cams, model, 0.5)
    assert view == 1 and np.flatnonzero(np.isfinite(seeded[0][:, 0])).tolist() == k, "3 seeds, all wrong"
    base = check_first_frame(inits, dots, cams, 0.5, model)
    assert np.isnan(base[0][0]).all()
    # Taken when 3 pairs after the growth are enough (the seeding as it was before the mend) ...
    out, _ = check_first_frame(inits, dots, cams, 0.5, model, one_view=3, confirm=3)
    np.testing.assert_allclose(out[0][k], lures, atol=1e-9)
    # ... refused at the default: the result is main's to the bit.
    for n in (3, 18):
        out, bad = check_first_frame(inits, dots, cams, 0.5, model, one_view=n)
        np.testing.assert_array_equal(bad, base[1])
        for v in range(2):
            np.testing.assert_array_equal(out[v], base[0][v])


def test_a_seeding_that_grows_no_further_than_the_pairs_left_is_not_taken():
    """4 right pairs left: main's growth reaches every marker, the seeding (one_view=18 acts) reaches
    no more, so main's result stands to the bit."""
    cams, model, uv, dots, inits = _failed_registration(0)
    right = [0, 3, 7, 10]
    inits[0][right] = uv[0][right]
    base = check_first_frame(inits, dots, cams, 0.5, model)
    assert np.all(np.isfinite(base[0][0])) and np.all(np.isfinite(base[0][1]))
    assert seed_from_one_view(inits, dots, cams, model, 0.5)[1] is not None, "the seeding has a view"
    out, bad = check_first_frame(inits, dots, cams, 0.5, model, one_view=18)
    np.testing.assert_array_equal(bad, base[1])
    for v in range(2):
        np.testing.assert_array_equal(out[v], base[0][v])
