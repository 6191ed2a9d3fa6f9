"""A marker's track that jumps (lipgen.recon.splitruns): all but its longest agreeing track taken back.

The 14-mark patch of tests/test_motioncheck.py sways before two views; its tracks are the true projections
plus 0.05 px of noise. A lure is a marker's sightings moved by a fixed 8 px in both views for some frames:
a feature beside the dot that moves with the lip, as the crease at a mouth corner does.
"""

from __future__ import annotations

import logging

import numpy as np
import pytest
from test_motioncheck import F, _marks
from test_raygap import _two_views

from lipgen.recon.splitruns import disagreeing_runs, split_runs_line, take_back_disagreeing
from lipgen.recon.track import LOST, TRACKED
from lipgen.recon.tracks import Tracks

M = 4
LURE = np.array([6.0, -5.0])      # 7.8 px: beyond the 5 px allowed, under the gap to a neighbour's dot


def _tracks(lure=(), lost=()):
    """Tracks of the swaying patch; M sits on the lure in the frames ``lure`` and is lost in ``lost``.
    Returns the tracks, the accepted sightings (F, P) and the layout in each view (2, P, 2)."""
    cams = _two_views()
    t = np.arange(F)[:, None]
    head = np.hstack([6 * np.sin(1.3 * t), 5 * np.cos(0.9 * t), 0 * t])   # the head moves, mm
    marks = _marks() + head[:, None]
    rng = np.random.default_rng(3)
    uv = np.stack([np.stack([c.project(m) for m in marks]) for c in cams])
    reference = uv[:, 0].copy()
    uv = uv + 0.05 * rng.standard_normal(uv.shape)
    for f in lure:
        uv[:, f, M] += LURE
    P = uv.shape[2]
    accepted = np.ones((F, P), dtype=bool)
    accepted[list(lost), M] = False
    uv[:, list(lost), M] = np.nan
    status = np.where(accepted, TRACKED, LOST).astype(np.int8)
    tracks = tuple(Tracks(uv[v].copy(), accepted.copy(), status.copy(), np.full((F, P), np.nan),
                          np.zeros((F, P), dtype=bool)) for v in range(2))
    return tracks, accepted, reference


def test_a_track_that_follows_its_neighbours_is_left_alone():
    tracks, accepted, ref = _tracks()
    step = np.linalg.norm(np.diff(tracks[1].uv[:, M], axis=0), axis=1)
    assert np.median(step) > 10, "the patch moves more between frames than the jump allowed"
    taken, groups = disagreeing_runs(tracks, accepted, ref, 5.0)
    assert not taken.any() and groups == []


def test_a_lure_before_the_dot_is_taken_back_and_the_longer_track_kept():
    tracks, accepted, ref = _tracks(lure=range(3), lost=[3, 4])
    taken, groups = disagreeing_runs(tracks, accepted, ref, 5.0)
    assert np.flatnonzero(taken[:, M]).tolist() == [0, 1, 2]
    assert taken[:, np.arange(taken.shape[1]) != M].sum() == 0
    assert groups == [{"marker": M, "kept": list(range(5, F)), "taken": [0, 1, 2]}]


def test_an_excursion_is_taken_back_and_the_track_on_either_side_joined():
    tracks, accepted, ref = _tracks(lure=[5, 6, 7])
    taken, groups = disagreeing_runs(tracks, accepted, ref, 5.0)
    assert np.flatnonzero(taken[:, M]).tolist() == [5, 6, 7]
    assert groups[0]["kept"] == [f for f in range(F) if f not in (5, 6, 7)]


def test_a_tie_takes_back_both_tracks():
    half = F // 2
    tracks, accepted, ref = _tracks(lure=range(half, 2 * half))
    taken, groups = disagreeing_runs(tracks, accepted, ref, 5.0)
    assert taken[: 2 * half, M].all() and groups[0]["kept"] == []


def test_a_move_within_the_limit_is_not_a_jump():
    tracks, accepted, ref = _tracks(lure=range(3), lost=[3, 4])
    assert not disagreeing_runs(tracks, accepted, ref, 9.0)[0].any(), "7.8 px is within 9"


def test_a_lip_that_deforms_fast_widens_the_limit_by_the_neighbours_spread():
    """From frame 5 every mark also moves 6 px a frame its own way (the lips deforming fast, unlike the
    head): the neighbours disagree on where M goes by about as much as M's move differs from their mean."""
    tracks, accepted, ref = _tracks()
    rng = np.random.default_rng(8)
    own = rng.standard_normal((F, accepted.shape[1], 2))
    own *= 6.0 / np.linalg.norm(own, axis=-1, keepdims=True)
    own[:5] = 0
    for v in range(2):
        tracks[v].uv[:] += np.cumsum(own, axis=0)
    assert disagreeing_runs(tracks, accepted, ref, 5.0)[0].any(), "split at a fixed 5 px"
    assert not disagreeing_runs(tracks, accepted, ref, 5.0, spread=2.0)[0].any()
    lured, seen, _ = _tracks(lure=range(3), lost=[3, 4])
    assert disagreeing_runs(lured, seen, ref, 5.0, spread=2.0)[0][:3, M].all(), "a rigid move: lure found"


def test_only_the_markers_judged_are_split():
    tracks, accepted, ref = _tracks(lure=range(3))
    judged = np.ones(accepted.shape[1], dtype=bool)
    judged[M] = False
    assert not disagreeing_runs(tracks, accepted, ref, 5.0, markers=judged)[0].any()


def test_take_back_returns_new_tracks_and_logs(caplog):
    tracks, accepted, ref = _tracks(lure=range(3), lost=[3, 4])
    names = [f"m{i}" for i in range(accepted.shape[1])]
    with caplog.at_level(logging.INFO, logger="lipgen.recon.splitruns"):
        new, groups = take_back_disagreeing(tracks, accepted, ref, 5.0, names=names)
    for v in range(2):
        assert np.isnan(new[v].uv[:3, M]).all() and (new[v].status[:3, M] == LOST).all()
        assert new[v].rejected[:3, M].all()
        np.testing.assert_array_equal(new[v].uv[5:], tracks[v].uv[5:])
        assert np.isfinite(tracks[v].uv[:3, M]).all(), "the tracks given are not changed"
    assert "m4 jumps between its accepted frames: 5 frame(s) kept, 3 taken back (0, 1, 2)" in caplog.text
    assert split_runs_line(groups) == ("Split tracks: 1 marker(s) jumped between accepted frames; 3 "
                                       "sighting(s) off the kept tracks taken back.")
    assert split_runs_line([]) == "Split tracks: no marker's track jumped between accepted frames."
    tie = [{"marker": M, "kept": [], "taken": [0, 1, 2, 3]}]
    assert split_runs_line(tie) == ("Split tracks: 1 marker(s) jumped between accepted frames (1 of them "
                                    "with no track long enough to keep); 4 sighting(s) off the kept tracks "
                                    "taken back.")
    assert split_runs_line(None) is None


@pytest.mark.parametrize("bad, match", [
    (dict(jump=0.0), "jump must be a positive number of pixels, got 0.0"),
    (dict(jump=np.nan), "jump must be a positive number"),
    (dict(accepted=np.ones((3, 14), dtype=bool)), r"accepted has shape \(3, 14\)"),
    (dict(reference=np.zeros((14, 2))), r"reference must be \(2, 14, 2\), got shape \(14, 2\)"),
    (dict(spread=-1.0), "spread must be a number >= 0, got -1.0"),
    (dict(ratio=0.5), "ratio must be a number >= 1, got 0.5"),
])
def test_bad_inputs_are_refused_with_the_value_named(bad, match):
    tracks, accepted, ref = _tracks()
    args = dict(accepted=accepted, reference=ref, jump=5.0) | bad
    with pytest.raises(ValueError, match=match):
        disagreeing_runs(tracks, **args)


@pytest.mark.parametrize("value", [0, -1.0, True, "5", np.inf])
def test_the_setting_is_checked(value):
    from lipgen.recon.settings import ReconstructSettings
    with pytest.raises(ValueError, match=r"settings.split_runs must be None or a positive number of pixels"):
        ReconstructSettings(split_runs=value)



@pytest.mark.parametrize("name, value, match", [("split_runs_ratio", 0.5, "a number >= 1"),
                                                 ("split_runs_ratio", True, "a number >= 1"),
                                                 ("split_runs_spread", -1.0, "a number >= 0"),
                                                 ("split_runs_spread", "2", "a number >= 0")])
def test_the_ratio_and_spread_settings_are_checked(name, value, match):
    from lipgen.recon.settings import ReconstructSettings
    with pytest.raises(ValueError, match=f"settings.{name} must be {match}, got {value!r}"):
        ReconstructSettings(**{name: value})
