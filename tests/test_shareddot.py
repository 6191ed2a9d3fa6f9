"""Two markers on one dot in both views (lipgen.recon.shareddot): both sightings are taken back.

The 14-mark patch of tests/test_motioncheck.py sways before two views (marks 5 mm apart in a row, rows
6 mm apart); its tracks are the true projections plus 0.05 px of noise. A wrong marker is put on a
neighbour's dot in both views: its rays meet at a real mark's point, so the one-marker checks pass.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_motioncheck import _marks
from test_raygap import _two_views

from lipgen.recon.shareddot import shared_dot_line, shared_dots, take_back_shared
from lipgen.recon.track import LOST, TRACKED
from lipgen.recon.tracks import Tracks
from lipgen.rig.pinhole import triangulate

OWNER, INTRUDER = 3, 4     # neighbours in a row, 5 mm apart


def _tracks(intrude=()):
    """Tracks of the swaying patch; in the frames ``intrude`` INTRUDER's sightings are OWNER's dot."""
    cams = _two_views()
    marks = _marks()
    rng = np.random.default_rng(5)
    uv = np.stack([np.stack([c.project(m) for m in marks]) for c in cams])
    uv = uv + 0.05 * rng.standard_normal(uv.shape)
    for f in intrude:
        uv[:, f, INTRUDER] = uv[:, f, OWNER] + 0.02
    F, P = uv.shape[1:3]
    tracks = tuple(Tracks(uv[v].copy(), np.ones((F, P), dtype=bool), np.full((F, P), TRACKED, dtype=np.int8),
                          np.full((F, P), np.nan), np.zeros((F, P), dtype=bool)) for v in range(2))
    return tracks, cams


def test_two_markers_on_one_dot_are_both_taken_back_and_nothing_else():
    tracks, cams = _tracks(intrude=range(3, 9))
    both = triangulate(cams[1], tracks[1].uv[3:9, [OWNER, INTRUDER]].reshape(-1, 2),
                       cams[0], tracks[0].uv[3:9, [OWNER, INTRUDER]].reshape(-1, 2))[1]
    assert both.max() < 0.1, "the rays meet: the ray gap cannot see it"
    new, spans = take_back_shared(tracks, tol=1.0)
    assert spans == [{"markers": (OWNER, INTRUDER), "frames": (3, 9)}]
    for v in range(2):
        for m in (OWNER, INTRUDER):
            assert np.isnan(new[v].uv[3:9, m]).all() and (new[v].status[3:9, m] == LOST).all()
            assert new[v].rejected[3:9, m].all() and not new[v].visible[3:9, m].any()
        keep = np.ones(new[v].visible.shape, dtype=bool)
        keep[3:9, [OWNER, INTRUDER]] = False
        np.testing.assert_array_equal(new[v].uv[keep], tracks[v].uv[keep])
        assert tracks[v].visible.all(), "the tracks given are not changed"


def test_two_spans_are_told_apart_and_right_tracks_are_left_alone():
    tracks, _ = _tracks(intrude=[1, 2, 7])
    taken, spans = shared_dots(tracks, tol=1.0)
    assert [s["frames"] for s in spans] == [(1, 3), (7, 8)]
    assert taken.sum() == 6 and taken[[1, 2, 7]][:, [OWNER, INTRUDER]].all()
    right, _ = _tracks()
    taken, spans = shared_dots(right, tol=1.0)
    assert spans == [] and not taken.any()
    new, _ = take_back_shared(right, tol=1.0)
    assert new is right, "nothing taken back: the same tracks"


def test_one_dot_means_one_dot_in_both_views():
    tracks, _ = _tracks(intrude=[4])
    tracks[0].uv[4, INTRUDER] += [1.5, 0.0]          # apart in one view: two dots, not judged here
    taken, spans = shared_dots(tracks, tol=1.0)
    assert spans == [] and not taken.any()
    assert shared_dots(tracks, tol=2.0)[1] == [{"markers": (OWNER, INTRUDER), "frames": (4, 5)}]
    for t in tracks:
        t.visible[4, OWNER], t.status[4, OWNER], t.uv[4, OWNER] = False, LOST, np.nan
    assert shared_dots(tracks, tol=2.0)[1] == [], "a lost marker holds no dot"


def test_three_markers_on_one_dot_are_all_taken_back():
    tracks, _ = _tracks(intrude=[2])
    for t in tracks:
        t.uv[2, 9] = t.uv[2, OWNER] - 0.02
    taken, spans = shared_dots(tracks, tol=1.0)
    assert [s["markers"] for s in spans] == [(OWNER, INTRUDER), (OWNER, 9), (INTRUDER, 9)]
    assert np.flatnonzero(taken[2]).tolist() == [OWNER, INTRUDER, 9] and taken.sum() == 3


@pytest.mark.parametrize("tol", [0.0, -1.0, np.nan, np.inf, True, "1"])
def test_a_bad_tolerance_is_named(tol):
    tracks, _ = _tracks()
    with pytest.raises(ValueError, match="tol must be a number > 0"):
        shared_dots(tracks, tol)


def test_tracks_of_two_shapes_are_refused():
    tracks, _ = _tracks()
    t = tracks[1]
    short = Tracks(t.uv[:, :5], t.visible[:, :5], t.status[:, :5], t.score[:, :5])
    with pytest.raises(ValueError, match=r"shape \(F, P, 2\), got \(10, 14, 2\) and \(10, 5, 2\)"):
        shared_dots((tracks[0], short), 1.0)


def test_the_line_names_the_markers_and_the_frames():
    names = ["a", "b", "c"]
    assert shared_dot_line([], names) is None and shared_dot_line(None, names) is None
    line = shared_dot_line([{"markers": [0, 2], "frames": [0, 25]}, {"markers": [1, 2], "frames": [30, 31]}],
                           names)
    assert line == ("Two markers held one dot in both views, so both were taken back there (one of them is "
                    "on the other's dot): a and c in frames 0-24; b and c in frame 30.")
    many = shared_dot_line([{"markers": [0, 1], "frames": [f, f + 1]} for f in range(0, 12, 2)], names)
    assert many.endswith("a and b in frame 6; and 2 more span(s).")
