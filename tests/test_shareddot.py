"""Two markers on one dot in both views (lipgen.recon.shareddot).

The 14-mark patch of tests/test_motioncheck.py sways before two views (marks 5 mm apart in a row, rows
6 mm apart); its tracks are the true projections plus 0.05 px of noise. A wrong marker is put on a
neighbour's dot in both views: its rays meet at a real mark's point, so the one-marker checks pass.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_motioncheck import _layout, _marks, _smooth_covariance
from test_raygap import _two_views

from lipgen.recon.shareddot import shared_dot_line, shared_dots, take_back_shared
from lipgen.recon.track import LOST, TRACKED
from lipgen.recon.tracks import Tracks

OWNER, INTRUDER = 3, 4     # neighbours in a row, 5 mm apart


def _tracks(intrude=(), onto_middle=False):
    """Tracks of the swaying patch; in the frames ``intrude`` INTRUDER's sightings are OWNER's dot
    (with ``onto_middle``, both markers sit on one dot midway between their marks)."""
    cams = _two_views()
    marks = _marks()
    rng = np.random.default_rng(5)
    uv = np.stack([np.stack([c.project(m) for m in marks]) for c in cams])
    uv = uv + 0.05 * rng.standard_normal(uv.shape)
    for f in intrude:
        if onto_middle:
            mid = 0.5 * (marks[f, OWNER] + marks[f, INTRUDER])
            uv[:, f, OWNER] = uv[:, f, INTRUDER] = [c.project(mid[None])[0] for c in cams]
        else:
            uv[:, f, INTRUDER] = uv[:, f, OWNER] + 0.02
    F, P = uv.shape[1:3]
    tracks = tuple(Tracks(uv[v].copy(), np.ones((F, P), dtype=bool), np.full((F, P), TRACKED, dtype=np.int8),
                          np.full((F, P), np.nan), np.zeros((F, P), dtype=bool)) for v in range(2))
    return tracks, cams


@pytest.mark.parametrize("covariance", [None, _smooth_covariance()], ids=["offsets", "physics"])
def test_the_marker_on_its_neighbours_dot_is_taken_back_and_the_owner_keeps_it(covariance):
    tracks, cams = _tracks(intrude=range(3, 9))
    new, spans = take_back_shared(tracks, cams, _layout(), tol=1.0, covariance=covariance)
    assert len(spans) == 1
    span = spans[0]
    assert span["markers"] == (OWNER, INTRUDER) and span["frames"] == (3, 9) and span["owner"] == OWNER
    d_owner, d_intruder = span["distance"]
    assert d_owner < 1.0 and 3.5 < d_intruder < 6.5, "the layout puts the intruder about a spacing away"
    for v in range(2):
        assert np.isnan(new[v].uv[3:9, INTRUDER]).all() and (new[v].status[3:9, INTRUDER] == LOST).all()
        assert new[v].rejected[3:9, INTRUDER].all() and not new[v].visible[3:9, INTRUDER].any()
        keep = np.ones(new[v].visible.shape, dtype=bool)
        keep[3:9, INTRUDER] = False
        np.testing.assert_array_equal(new[v].uv[keep], tracks[v].uv[keep])
        assert tracks[v].visible.all(), "the tracks given are not changed"


def test_a_dot_neither_marker_is_nearer_is_taken_back_from_both():
    tracks, cams = _tracks(intrude=[5, 6], onto_middle=True)
    taken, spans = shared_dots(tracks, cams, _layout(), tol=1.0)
    assert [s["owner"] for s in spans] == [-1]
    expected = np.zeros(taken.shape, dtype=bool)
    expected[5:7, [OWNER, INTRUDER]] = True
    np.testing.assert_array_equal(taken, expected)


def test_two_spans_are_judged_apart_and_right_tracks_are_left_alone():
    tracks, cams = _tracks(intrude=[1, 2, 7])
    taken, spans = shared_dots(tracks, cams, _layout(), tol=1.0)
    assert [s["frames"] for s in spans] == [(1, 3), (7, 8)]
    assert taken.sum() == 3 and taken[[1, 2, 7], INTRUDER].all()
    right, _ = _tracks()
    taken, spans = shared_dots(right, cams, _layout(), tol=1.0)
    assert spans == [] and not taken.any()
    new, _ = take_back_shared(right, cams, _layout(), tol=1.0)
    assert new is right, "nothing taken back: the same tracks"


def test_one_dot_means_one_dot_in_both_views():
    tracks, cams = _tracks(intrude=[4])
    tracks[0].uv[4, INTRUDER] += 1.5                 # apart in one view: two dots, not judged here
    taken, spans = shared_dots(tracks, cams, _layout(), tol=1.0)
    assert spans == [] and not taken.any()
    for t in tracks:
        t.visible[4, OWNER], t.status[4, OWNER], t.uv[4, OWNER] = False, LOST, np.nan
    assert shared_dots(tracks, cams, _layout(), tol=1.0)[1] == [], "a lost marker holds no dot"


def test_a_span_without_a_prediction_is_taken_back_from_both():
    tracks, cams = _tracks(intrude=[4])
    for t in tracks:                                   # 5 other pairs: under min_pairs = 6
        t.visible[4, 7:], t.status[4, 7:], t.uv[4, 7:] = False, LOST, np.nan
    taken, spans = shared_dots(tracks, cams, _layout(), tol=1.0)
    assert spans[0]["owner"] == -1 and spans[0]["distance"] is None
    assert taken[4, [OWNER, INTRUDER]].all() and taken.sum() == 2


@pytest.mark.parametrize("kwargs, match", [
    ({"tol": 0.0}, "tol must be > 0"), ({"tol": np.nan}, "tol must be > 0"),
    ({"tol": 1.0, "ratio": 1.5}, "ratio in"),
    ({"tol": 1.0, "rest_points": np.zeros((13, 3))}, r"rest_points \(13, 3\)")])
def test_bad_settings_and_shapes_are_named(kwargs, match):
    tracks, cams = _tracks()
    kwargs = {"rest_points": _layout()} | kwargs
    with pytest.raises(ValueError, match=match):
        shared_dots(tracks, cams, **kwargs)


def test_the_line_names_who_kept_the_dot_and_who_was_taken_back():
    names = ["a", "b", "c"]
    assert shared_dot_line([], names) is None and shared_dot_line(None, names) is None
    line = shared_dot_line([{"markers": [0, 2], "frames": [0, 25], "owner": 0, "distance": [1.0, 4.0]},
                            {"markers": [1, 2], "frames": [30, 31], "owner": -1, "distance": None}], names)
    assert line == ("Two markers held one dot in both views: c on a's in frames 0-24, taken back; b and c in "
                    "frame 30, both taken back (the layout could not tell whose).")
