"""The continuity judge of the cross-check (lipgen.recon.continuity): a disputed span goes to the run whose
sightings at its ends carry on the motion both runs agreed on outside it; undecided without an agreed
neighbour; in arbitrate it overrides the layout; bad input."""

from dataclasses import replace

import numpy as np
import pytest
from test_crosscheck import _layout_rig, _tracks

from lipgen.recon.association import LOST
from lipgen.recon.continuity import continuity_verdict, span_jumps
from lipgen.recon.crosscheck import arbitrate
from lipgen.recon.tracks import seen, true_runs

F = 10


def _runs(speed=2.0, slip=(6.0, 0.0)):
    """Two markers moving down at ``speed`` px per frame in both views; in frames 3-6 the first run has
    marker 0 on a dot ``slip`` away, the second run on its own dot."""
    t = np.arange(F, dtype=float)
    right = np.stack([np.c_[100 + 0 * t, 50 + speed * t], np.c_[140 + 0 * t, 50 + speed * t]], axis=1)
    wrong = right.copy()
    wrong[3:7, 0] += slip
    disputed = np.zeros((F, 2), bool)
    disputed[3:7, 0] = True
    return (_tracks(wrong), _tracks(wrong + 30)), (_tracks(right), _tracks(right + 30)), disputed


def test_the_run_that_carries_the_agreed_motion_on_wins_either_way_round():
    slipped, stayed, disputed = _runs()
    v = continuity_verdict(slipped, stayed, disputed)
    assert (v[3:7, 0] == 2).all() and (v[~disputed] == 0).all()
    assert (continuity_verdict(stayed, slipped, disputed)[3:7, 0] == 1).all()
    ja, jb, n = span_jumps(slipped, stayed, disputed, 0, 3, 7)
    assert n == 4 and jb == pytest.approx(0.0, abs=1e-9) and ja == pytest.approx(4 * 6.0)


def test_the_agreed_velocity_carries_the_reference_on():
    # the wrong run stuck where the marker was at frame 2 and at frame 7; the right one moved on at 5 px
    slipped, stayed, disputed = _runs(speed=5.0)
    uv = stayed[0].uv.copy()
    uv[3:7, 0] = [uv[2, 0]] * 2 + [uv[7, 0]] * 2
    stuck = (_tracks(uv), _tracks(uv + 30))
    assert (continuity_verdict(stuck, stayed, disputed)[3:7, 0] == 2).all()


def test_without_an_agreed_neighbour_or_a_clear_winner_the_span_is_undecided():
    slipped, stayed, disputed = _runs()
    # frames 2 and 7 seen by the second run only: its own track is no reference
    one_sided = []
    for t in slipped:
        uv = t.uv.copy()
        uv[[2, 7], 0] = np.nan
        one_sided.append(_tracks(uv))
    assert (continuity_verdict(tuple(one_sided), stayed, disputed)[3:7, 0] == 0).all()
    # both runs jump about as far
    uv_a, uv_b = stayed[0].uv.copy(), stayed[0].uv.copy()
    uv_a[3:7, 0] += [4.0, 0]
    uv_b[3:7, 0] -= [4.5, 0]
    v = continuity_verdict((_tracks(uv_a), stayed[1]), (_tracks(uv_b), stayed[1]), disputed)
    assert (v[3:7, 0] == 0).all()


def test_in_arbitrate_continuity_overrides_a_layout_that_prefers_the_wrong_run():
    rest, cams = _layout_rig()
    X = np.repeat(rest[None], F, axis=0)
    X[:, 4] += np.arange(F)[:, None] * [1.0, 0, 0]    # marker 4 moves 1 mm a frame away from rest
    at_rest = X.copy()
    at_rest[3:7, 4] = rest[4]                         # the first run: on a dot where the layout expects it
    runs = [tuple(_tracks(np.stack([c.project(Xf) for Xf in P3])) for c in cams) for P3 in (at_rest, X)]
    disputed = np.zeros((F, 12), bool)
    disputed[3:7, 4] = True
    assert (arbitrate(runs[0], runs[1], disputed, cams, rest)[3:7, 4] == 1).all()
    assert (arbitrate(runs[0], runs[1], disputed, cams, rest, continuity=True)[3:7, 4] == 2).all()


def test_bad_input_is_refused_with_the_shape_or_value():
    slipped, stayed, disputed = _runs()
    with pytest.raises(ValueError, match=r"disputed must be \(F, P\) = \(10, 2\), got \(10, 3\)"):
        continuity_verdict(slipped, stayed, np.zeros((F, 3), bool))
    with pytest.raises(ValueError, match="ratio must be in"):
        continuity_verdict(slipped, stayed, disputed, ratio=1.5)


def test_the_shared_helpers_seen_and_true_runs():
    assert true_runs(np.array([0, 1, 1, 0, 1], bool)) == [(1, 3), (4, 5)]
    assert true_runs(np.zeros(3, bool)) == [] and true_runs(np.ones(2, bool)) == [(0, 2)]
    uv = np.zeros((2, 2, 2))
    uv[0, 1] = np.nan
    t = _tracks(uv)
    status = t.status.copy()
    status[1, 0] = LOST                               # lost with a finite position: not seen
    np.testing.assert_array_equal(seen(t), [[True, False], [True, True]])
    np.testing.assert_array_equal(seen(replace(t, status=status)), [[True, False], [False, True]])
