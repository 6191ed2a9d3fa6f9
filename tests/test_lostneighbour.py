"""The last pass over the tracks: a marker's run on a lost neighbour's place (lipgen.recon.lostneighbour).

The 14-mark patch of tests/test_motioncheck.py (5 mm apart along a row, rows 6 mm apart) sways
before two views; its tracks are the true projections. Mark NB is lost in both views all clip;
mark A's sightings are, from frame ``wrong_from``, the projections of NB's mark (an identity shift
onto the lost neighbour's dot), or of a point 8 mm below its own (a lure on nobody's place).
"""

from __future__ import annotations

import numpy as np
import pytest
from test_motioncheck import _layout, _marks
from test_raygap import _two_views

from lipgen.recon.lostneighbour import close_neighbours, lost_neighbour_runs, runs, take_back_lost_neighbour
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.track import LOST, TRACKED
from lipgen.recon.tracks import Tracks

A, NB = 3, 4


def _tracks(on_neighbour=False, lure=0.0, wrong_from=0, lose_nb=True):
    cams = _two_views()
    marks = _marks()
    seen = marks.copy()
    if on_neighbour:
        seen[wrong_from:, A] = marks[wrong_from:, NB]
    seen[wrong_from:, A, 1] -= lure
    uv = np.stack([np.stack([c.project(m) for m in seen]) for c in cams])
    F, P = uv.shape[1:3]
    status = np.full((F, P), TRACKED, dtype=np.int8)
    if lose_nb:
        uv[:, :, NB] = np.nan
        status[:, NB] = LOST
    tracks = tuple(Tracks(uv[v].copy(), status != LOST, status.copy(), np.full((F, P), np.nan),
                          np.zeros((F, P), dtype=bool)) for v in range(2))
    return tracks, cams


def test_runs_and_neighbours():
    assert runs([0, 1, 1, 0, 1]) == [(1, 3), (4, 5)]
    assert runs([1, 1]) == [(0, 2)] and runs([0, 0]) == []
    near, judged, width = close_neighbours(_layout())
    assert 5.0 <= width <= 5.3  # 5 mm along the curved row
    assert near[A, NB] and near[A, A + 7] and not near[A, A + 9] and not near[A, A + 2] and not near[A, A]
    assert judged.all()


def test_a_marker_on_its_lost_neighbours_place_is_taken_back_and_nothing_else():
    tracks, cams = _tracks(on_neighbour=True)
    new, taken = take_back_lost_neighbour(tracks, cams, _layout())
    expected = np.zeros(taken.shape, dtype=bool)
    expected[:, A] = True
    np.testing.assert_array_equal(taken, expected)
    for v in range(2):
        assert np.isnan(new[v].uv[:, A]).all() and (new[v].status[:, A] == LOST).all()
        assert new[v].rejected[:, A].all()
        assert tracks[v].visible[:, A].all(), "the tracks given are not changed"


def test_only_the_wrong_run_goes():
    tracks, cams = _tracks(on_neighbour=True, wrong_from=5)
    for t in tracks:  # a gap at frames 3-4 splits A's right run from its wrong one
        t.uv[3:5, A], t.status[3:5, A], t.visible[3:5, A] = np.nan, LOST, False
    taken = lost_neighbour_runs(tracks, cams, _layout())
    assert taken[5:, A].all() and not taken[:5].any() and taken.sum() == len(taken) - 5


def test_right_tracks_are_left_alone():
    tracks, cams = _tracks()
    assert not lost_neighbour_runs(tracks, cams, _layout()).any()
    assert not lost_neighbour_runs(tracks, cams, _layout(), neither=0.5).any()
    tracks, cams = _tracks(on_neighbour=True, lose_nb=False)  # the neighbour seen: not this check's case
    assert not lost_neighbour_runs(tracks, cams, _layout()).any()


def test_a_lure_on_nobodys_place_goes_only_with_neither():
    tracks, cams = _tracks(lure=8.0)
    assert not lost_neighbour_runs(tracks, cams, _layout()).any()
    taken = lost_neighbour_runs(tracks, cams, _layout(), neither=0.5)
    assert taken[:, A].all() and taken.sum() == len(taken)
    tracks, cams = _tracks(lure=1.0)  # 1 mm: within half a spacing of its place
    assert not lost_neighbour_runs(tracks, cams, _layout(), neither=0.5).any()


def test_bad_arguments_and_settings_are_refused():
    tracks, cams = _tracks()
    with pytest.raises(ValueError, match="ratio"):
        lost_neighbour_runs(tracks, cams, _layout(), ratio=0.0)
    with pytest.raises(ValueError, match="neither"):
        lost_neighbour_runs(tracks, cams, _layout(), neither=-1.0)
    with pytest.raises(ValueError, match="lost_neighbour_ratio"):
        ReconstructSettings(lost_neighbour_ratio=1.5)
    with pytest.raises(ValueError, match="lost_neighbour_neither"):
        ReconstructSettings(lost_neighbour_ratio=0.5, lost_neighbour_neither=float("nan"))
    with pytest.raises(ValueError, match="set both"):
        ReconstructSettings(lost_neighbour_neither=0.5)
    assert ReconstructSettings().lost_neighbour_ratio is None


def test_track_raw_frames_runs_the_pass_after_out_of_place_only_when_set(monkeypatch):
    from test_shifted import _two_view_frames

    import lipgen.recon.steps as steps

    raws, layout, expected, cams, X = _two_view_frames()
    calls = []
    place, lost = steps.take_back_out_of_place, steps.take_back_lost_neighbour
    monkeypatch.setattr(steps, "take_back_out_of_place",
                        lambda *a, **kw: calls.append("place") or place(*a, **kw))
    monkeypatch.setattr(steps, "take_back_lost_neighbour",
                        lambda *a, **kw: calls.append(("lost", kw["ratio"], kw["neither"])) or lost(*a, **kw))
    steps.track_raw_frames(iter(raws), layout, expected, ReconstructSettings(), cameras=cams, rest_points=X)
    assert calls == ["place"], "off by default"
    calls.clear()
    on = ReconstructSettings(lost_neighbour_ratio=0.5, lost_neighbour_neither=0.5)
    steps.track_raw_frames(iter(raws), layout, expected, on, cameras=cams, rest_points=X)
    assert calls == ["place", ("lost", 0.5, 0.5)]
