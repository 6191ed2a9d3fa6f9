"""The forward-backward cross-check of marker labels (lipgen.recon.crosscheck): sightings the two runs put on
different dots are taken back in both views; agreement and one-sided sightings stand; the fill; the
reversed run in time order; bad input."""

import numpy as np
import pytest

from lipgen.recon.association import LOST, RECOVERED, TRACKED
from lipgen.recon.crosscheck import arbitrate, cross_check, reversed_run
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.tracks import Tracks

F, P = 5, 4


def _tracks(uv, status=TRACKED):
    """Tracks with the given positions; LOST where a position is NaN."""
    uv = np.array(uv, dtype=float)
    seen = np.all(np.isfinite(uv), axis=-1)
    st = np.where(seen, status, LOST).astype(np.int8)
    return Tracks(uv=uv, visible=seen, status=st, score=np.full(seen.shape, 0.9),
                  rejected=np.zeros(seen.shape, bool))


def _grid(seed=0):
    return np.random.default_rng(seed).uniform(10, 200, (F, P, 2))


def test_runs_that_agree_leave_the_tracks_as_they_were():
    a = (_tracks(_grid(0)), _tracks(_grid(1)))
    b = (_tracks(_grid(0) + 0.4), _tracks(_grid(1) - 0.4))    # the same dots, refined a little differently
    (v, r), record = cross_check(a, b, tol=2.0)
    assert record["dropped"] == 0 and record["filled"] == 0
    for new, old in zip((v, r), a, strict=True):
        np.testing.assert_array_equal(new.uv, old.uv)
        np.testing.assert_array_equal(new.status, old.status)
        assert not new.rejected.any()


def test_a_disagreement_in_one_view_takes_the_sighting_back_in_both():
    uv_b = _grid(0).copy()
    uv_b[2, 1] += [6.0, 0.0]  # the second run put marker 1 on another dot
    a = (_tracks(_grid(0)), _tracks(_grid(1)))
    (v, r), record = cross_check(a, (_tracks(uv_b), _tracks(_grid(1))), tol=2.0)
    assert record["dropped"] == 1
    for t in (v, r):
        assert t.status[2, 1] == LOST and not t.visible[2, 1]
        assert np.isnan(t.uv[2, 1]).all() and t.rejected[2, 1]
        changed = np.ones((F, P), bool)
        changed[2, 1] = False
        assert (t.status[changed] == TRACKED).all()


def test_a_sighting_only_one_run_has_stands_and_the_second_alone_adds_nothing():
    uv_a, uv_b = _grid(0).copy(), _grid(0).copy()
    uv_a[1, 0] = np.nan  # the first run lost marker 0 in frame 1 (virtual)
    uv_b[3, 2] = np.nan  # the second lost marker 2 in frame 3
    a = (_tracks(uv_a), _tracks(_grid(1)))
    b = (_tracks(uv_b), _tracks(_grid(1)))
    (v, r), record = cross_check(a, b, tol=2.0)
    assert record == {"dropped": 0, "filled": 0, "tol": 2.0, "kept": 0, "swapped": 0}
    np.testing.assert_array_equal(v.uv, uv_a)
    assert v.status[1, 0] == LOST and r.status[1, 0] == TRACKED


def test_the_fill_takes_the_second_runs_pair_only_where_it_agrees_with_the_first():
    uv_a = _grid(0).copy()
    uv_a[1, 0] = np.nan  # lost in the virtual view, seen in the real one
    real_a = _grid(1).copy()
    real_a[3, 2] = np.nan  # lost in the real view
    real_a[4, 3] = np.nan
    b_virtual, b_real = _grid(0).copy(), _grid(1).copy()
    b_virtual[4, 3] += [9.0, 0.0]  # the second run's virtual sighting is elsewhere
    a = (_tracks(uv_a), _tracks(real_a))
    b = (_tracks(b_virtual, RECOVERED), _tracks(b_real, RECOVERED))
    (v, r), record = cross_check(a, b, tol=2.0, fill=True)
    assert record["dropped"] == 1 and record["filled"] == 2    # (4, 3) disagrees in the virtual view
    for f, m in ((1, 0), (3, 2)):
        assert v.status[f, m] == RECOVERED and r.status[f, m] == RECOVERED
        np.testing.assert_array_equal(v.uv[f, m], b_virtual[f, m])
        np.testing.assert_array_equal(r.uv[f, m], b_real[f, m])
    assert v.status[4, 3] == LOST and r.status[4, 3] == LOST
    (v0, _), record0 = cross_check(a, b, tol=2.0)
    assert record0["filled"] == 0 and v0.status[1, 0] == LOST


def test_the_reversed_run_is_made_on_the_reversed_clip_and_returned_in_time_order():
    runs = []

    def track(frames, progress):
        frames = [int(f) for f in frames]
        runs.append(frames)
        for t in range(len(frames)):
            if progress is not None:
                progress(t)
        uv = np.zeros((len(frames), P, 2))
        uv[..., 0] = np.asarray(frames, float)[:, None]      # u holds the frame index
        t = _tracks(uv)
        return t, t

    ticks = []
    (v, r), record = reversed_run(lambda i: i, 7, track, step=None, progress=ticks.append)
    assert runs == [[6, 5, 4, 3, 2, 1, 0]] and len(ticks) == 7        # progress once per frame
    np.testing.assert_array_equal(v.uv[:, 0, 0], np.arange(7))
    assert record["frame"] == 6


@pytest.mark.parametrize("tol", [0.0, -1.0, float("nan")])
def test_a_tolerance_that_is_not_a_positive_distance_is_refused(tol):
    a = (_tracks(_grid(0)), _tracks(_grid(1)))
    with pytest.raises(ValueError, match="tol must be a positive distance"):
        cross_check(a, a, tol=tol)


def test_runs_of_different_shapes_are_refused():
    a = (_tracks(_grid(0)), _tracks(_grid(1)))
    b = (_tracks(_grid(0)[:3]), _tracks(_grid(1)[:3]))
    with pytest.raises(ValueError, match="differ in shape"):
        cross_check(a, b, tol=2.0)


@pytest.mark.parametrize("name", ["cross_check", "cross_check_fill", "cross_check_pairs",
                                  "cross_check_spread", "cross_check_continuity"])
def test_the_settings_refuse_a_value_that_is_not_a_bool(name):
    with pytest.raises(ValueError, match=name):
        ReconstructSettings(**{name: 1})


def test_a_judge_keeps_the_first_run_takes_the_second_or_drops_per_its_verdict():
    uv_b = _grid(0).copy()
    uv_b[1:3, 0] += [6.0, 0.0]  # marker 0: the runs disagree in frames 1-2
    uv_b[4, 1] += [6.0, 0.0]  # marker 1: in frame 4
    uv_b[0, 2] += [6.0, 0.0]  # marker 2: in frame 0
    a = (_tracks(_grid(0)), _tracks(_grid(1)))
    b = (_tracks(uv_b, RECOVERED), _tracks(_grid(1), RECOVERED))
    seen = []

    def judge(first, second, disputed):
        seen.append(np.argwhere(disputed).tolist())
        out = np.zeros(disputed.shape, np.int8)
        out[:, 0], out[:, 1] = 1, 2
        return out

    (v, r), record = cross_check(a, b, tol=2.0, judge=judge)
    assert seen == [[[0, 2], [1, 0], [2, 0], [4, 1]]]
    assert record["kept"] == 2 and record["swapped"] == 1 and record["dropped"] == 1
    np.testing.assert_array_equal(v.uv[1:3, 0], _grid(0)[1:3, 0])  # kept: the first run's
    np.testing.assert_array_equal(v.uv[4, 1], uv_b[4, 1])  # swapped: the second run's pair
    assert v.status[4, 1] == RECOVERED and r.status[4, 1] == RECOVERED and v.rejected[4, 1]
    assert v.status[0, 2] == LOST and r.status[0, 2] == LOST  # undecided: dropped


def _layout_rig():
    """Twelve markers at rest, mm, and a (virtual, real) pair of cameras looking at them."""
    from lipgen.rig.pinhole import PinholeCamera

    rng = np.random.default_rng(3)
    rest = np.c_[rng.uniform(-25, 25, (12, 2)), rng.uniform(-5, 5, 12)]
    K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])

    def camera(angle):
        c, s = np.cos(np.radians(angle)), np.sin(np.radians(angle))
        R = np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]])
        return PinholeCamera(K=K, R=R, t=np.array([0.0, 0, 300]), width=640, height=480)

    return rest, (camera(-30.0), camera(10.0))


def test_arbitration_prefers_the_run_whose_points_fit_the_layout():
    rest, cams = _layout_rig()
    X = np.repeat(rest[None], 3, axis=0)  # 3 frames at rest
    wrong = X.copy()
    wrong[:, 4] += [6.0, 0, 0]  # the second run: marker 4 on a dot 6 mm off
    runs = [tuple(_tracks(np.stack([c.project(Xf) for Xf in P3])) for c in cams) for P3 in (X, wrong)]
    disputed = np.zeros((3, 12), bool)
    disputed[:, 4] = True
    assert (arbitrate(runs[0], runs[1], disputed, cams, rest)[:, 4] == 1).all()
    assert (arbitrate(runs[1], runs[0], disputed, cams, rest)[:, 4] == 2).all()


def test_with_spread_a_point_off_along_the_priors_loose_direction_beats_a_nearer_one_off_across_it():
    rest, cams = _layout_rig()
    cov = 0.1 * np.eye(36)
    cov[12, 12] = 10.0                          # marker 4 moves freely in x only (a corner along the mouth)
    X = np.repeat(rest[None], 3, axis=0)
    along, across = X.copy(), X.copy()
    along[:, 4] += [5.0, 0, 0]                  # the first run: 5 mm off, along x
    across[:, 4] += [0, 2.5, 0]                 # the second run: 2.5 mm off, across
    runs = [tuple(_tracks(np.stack([c.project(Xf) for Xf in P3])) for c in cams) for P3 in (along, across)]
    disputed = np.zeros((3, 12), bool)
    disputed[:, 4] = True
    assert (arbitrate(runs[0], runs[1], disputed, cams, rest, cov)[:, 4] == 2).all()    # mm: the nearer
    assert (arbitrate(runs[0], runs[1], disputed, cams, rest, cov, spread=True)[:, 4] == 1).all()
    assert (arbitrate(runs[1], runs[0], disputed, cams, rest, cov, spread=True)[:, 4] == 2).all()
    # without a prior there is no spread to measure against: mm, as before
    assert (arbitrate(runs[0], runs[1], disputed, cams, rest, None, spread=True)[:, 4] == 2).all()


def test_with_pairs_a_frame_only_one_run_sees_in_both_views_goes_to_that_run():
    rest, cams = _layout_rig()
    X = np.repeat(rest[None], 3, axis=0)
    right = [_tracks(np.stack([c.project(Xf) for Xf in X])) for c in cams]
    one_view = [_tracks(np.stack([c.project(Xf) for Xf in X])) for c in cams]
    one_view[1].uv[:, 4] += [9.0, 0.0]          # the real view on another dot...
    one_view[0].uv[:2, 4] = np.nan              # ...and the virtual view lost in frames 0-1
    one_view[0].status[:2, 4] = LOST
    disputed = np.zeros((3, 12), bool)
    disputed[:, 4] = True
    plain = arbitrate(tuple(one_view), tuple(right), disputed, cams, rest)
    paired = arbitrate(tuple(one_view), tuple(right), disputed, cams, rest, pairs=True)
    back = arbitrate(tuple(right), tuple(one_view), disputed, cams, rest, pairs=True)
    # frame 2, where both runs have a pair, is judged by the layout over the span in every case
    assert plain[2, 4] == paired[2, 4] == 2 and back[2, 4] == 1
    assert (plain[:2, 4] == 2).all()            # the span's verdict, from frame 2, covers frames 0-1
    assert (paired[:2, 4] == 2).all() and (back[:2, 4] == 1).all()
    assert (paired[:, :4] == 0).all() and (paired[:, 5:] == 0).all()   # nothing else disputed


def test_with_pairs_an_unjudged_span_goes_to_the_run_with_the_pair():
    rest, cams = _layout_rig()
    X = np.repeat(rest[None], 3, axis=0)
    right = [_tracks(np.stack([c.project(Xf) for Xf in X])) for c in cams]
    one_view = [_tracks(np.stack([c.project(Xf) for Xf in X])) for c in cams]
    one_view[1].uv[:, 4] += [9.0, 0.0]
    one_view[0].uv[:, 4] = np.nan               # the first run never sees marker 4 in the virtual view
    one_view[0].status[:, 4] = LOST
    disputed = np.zeros((3, 12), bool)
    disputed[:, 4] = True
    assert (arbitrate(tuple(one_view), tuple(right), disputed, cams, rest)[:, 4] == 0).all()
    assert (arbitrate(tuple(one_view), tuple(right), disputed, cams, rest, pairs=True)[:, 4] == 2).all()
    assert (arbitrate(tuple(right), tuple(one_view), disputed, cams, rest, pairs=True)[:, 4] == 1).all()


def test_with_pairs_a_pair_far_from_the_layout_does_not_beat_a_single_sighting_on_the_marker():
    rest, cams = _layout_rig()
    X = np.repeat(rest[None], 3, axis=0)
    single = [_tracks(np.stack([c.project(Xf) for Xf in X])) for c in cams]
    single[0].uv[:, 4] = np.nan                 # the first run: marker 4 right, in the real view only
    single[0].status[:, 4] = LOST
    elsewhere = X.copy()
    elsewhere[:, 4] = rest[7]                   # the second run: a pair on marker 7's dot
    pair = [_tracks(np.stack([c.project(Xf) for Xf in elsewhere])) for c in cams]
    disputed = np.zeros((3, 12), bool)
    disputed[:, 4] = True
    assert (arbitrate(tuple(single), tuple(pair), disputed, cams, rest, pairs=True)[:, 4] == 0).all()


def test_keeping_undecided_disputes_leaves_the_first_runs_sightings():
    uv_b = _grid(0).copy()
    uv_b[2, 1] += [6.0, 0.0]
    a = (_tracks(_grid(0)), _tracks(_grid(1)))
    (v, r), record = cross_check(a, (_tracks(uv_b), _tracks(_grid(1))), tol=2.0, keep_undecided=True)
    assert record["dropped"] == 0 and record["kept"] == 1
    np.testing.assert_array_equal(v.uv, _grid(0))
    assert (v.status == TRACKED).all() and (r.status == TRACKED).all()


def test_the_line_says_what_the_second_run_changed():
    from lipgen.recon.crosscheck import cross_check_line

    assert cross_check_line(None) is None and cross_check_line({}) is None     # tracked once
    record = {"dropped": 1, "kept": 8, "swapped": 2, "filled": 30, "tol": 2.5, "anchor": {"frame": 39}}
    line = cross_check_line(record)
    assert "in reverse from frame 39" in line and "11 marker sighting(s) on different dots" in line
    assert "(8 kept from the first run, 2 taken from the second, 1 dropped)" in line
    assert "30 sighting(s) the first run lacked" in line
    assert "from frame" not in cross_check_line(record | {"anchor": {}})
