"""Accepted tracks walked on into the frames where the marker was lost (:mod:`lipgen.recon.extend`)."""

from __future__ import annotations

import numpy as np
import pytest
from test_gapfill import DOTS, GRID, _accepted, _clip, _lose

from lipgen.recon.association import LOST, RECOVERED, TRACKED
from lipgen.recon.extend import extend_line, extend_tracks
from lipgen.recon.settings import ReconstructSettings

F, P = 12, len(GRID)


def _reference(cams):
    return np.stack([c.project(GRID) for c in cams])


def _walk(cams, images, tracks, **kw):
    return extend_tracks(tracks, lambda f: images[f], cams, _accepted(tracks), _reference(cams), DOTS, 0.05,
                         1.0, 3.0, **kw)


def test_a_marker_lost_to_the_clips_end_or_from_its_start_is_walked_on_its_own_dots():
    cams, uv, images, tracks = _clip()
    _lose(tracks, list(range(4, F)), 5)          # lost from frame 4 to the end, in both views
    _lose(tracks, [0, 1, 2], 9)                  # lost from the start to frame 2
    out, record = _walk(cams, images, tracks)
    assert record == {"walks": 2, "walked": 8 + 3}
    for v in range(2):
        assert np.linalg.norm(out[v].uv[4:, 5] - uv[v, 4:, 5], axis=1).max() < 0.5
        assert np.linalg.norm(out[v].uv[:3, 9] - uv[v, :3, 9], axis=1).max() < 0.5
        assert (out[v].status[4:, 5] == RECOVERED).all() and out[v].visible[4:, 5].all()
        assert (out[v].status[3:, 9] == TRACKED).all()
    assert tracks[0].status[4, 5] == LOST, "the input tracks are not changed"


def test_two_markers_taken_back_together_each_walk_to_their_own_dot():
    # As the shared-dot check leaves them: both lost from frame 5 on (one was on the other's dot).
    cams, uv, images, tracks = _clip()
    _lose(tracks, list(range(5, F)), 5)
    _lose(tracks, list(range(5, F)), 6)
    out, record = _walk(cams, images, tracks)
    assert record["walked"] == 2 * (F - 5)
    for v in range(2):
        for i in (5, 6):
            assert np.linalg.norm(out[v].uv[5:, i] - uv[v, 5:, i], axis=1).max() < 0.5


def test_the_walk_stops_where_the_dot_is_gone_and_starts_only_after_a_run_of_accepted_frames():
    drawn = np.ones((2, F, P), dtype=bool)
    drawn[:, 7:, 5] = False                      # the dot hidden from frame 7 on
    cams, uv, images, tracks = _clip(drawn)
    _lose(tracks, list(range(4, F)), 5)
    out, record = _walk(cams, images, tracks)
    assert record["walked"] == 3
    assert (out[0].status[4:7, 5] == RECOVERED).all() and (out[0].status[7:, 5] == LOST).all()
    _lose(tracks, [2], 5)                        # accepted in frames 0-1 and 3 only
    out, record = _walk(cams, images, tracks, min_run=3)
    assert record == {"walks": 0, "walked": 0}, "no run of 3 accepted frames to start from"
    out, record = _walk(cams, images, tracks, min_run=2)
    assert record == {"walks": 1, "walked": 1}, "frame 2 from frames 0-1; frame 3 alone starts nothing"
    assert out[1].status[2, 5] == RECOVERED and (out[1].status[4:, 5] == LOST).all()
    start = np.ones((F, P), dtype=bool)
    start[3, 5] = False                          # not a sighting a walk may start from
    out, record = _walk(cams, images, tracks, start=start)
    assert (out[1].status[4:, 5] == LOST).all()


def test_a_dot_another_marker_holds_is_not_taken():
    cams, uv, images, tracks = _clip()
    _lose(tracks, list(range(6, F)), 9)
    tracks[1].uv[6:, 10] = uv[1, 6:, 9]          # marker 10 (wrongly) holds marker 9's dot in view 1
    out, record = _walk(cams, images, tracks)
    assert record["walked"] == 0 and (out[0].status[6:, 9] == LOST).all()


def test_bad_inputs_are_refused_with_the_value_named():
    cams, uv, images, tracks = _clip()
    acc = _accepted(tracks)
    ref = _reference(cams)
    with pytest.raises(ValueError, match=r"accepted must have shape \(12, 12\)"):
        extend_tracks(tracks, lambda f: images[f], cams, acc[1:], _reference(cams), DOTS, 0.05, 1.0, 3.0)
    with pytest.raises(ValueError, match=r"reference must have shape \(2, 12, 2\)"):
        extend_tracks(tracks, lambda f: images[f], cams, acc, _reference(cams)[0], DOTS, 0.05, 1.0, 3.0)
    for bad in (0.0, -1.0, np.inf, True):
        with pytest.raises(ValueError, match="gate"):
            extend_tracks(tracks, lambda f: images[f], cams, acc, _reference(cams), DOTS, 0.05, 1.0, bad)
    with pytest.raises(ValueError, match="ratio"):
        extend_tracks(tracks, lambda f: images[f], cams, acc, _reference(cams), DOTS, 0.05, 1.0, 3.0, 1.5)
    with pytest.raises(ValueError, match=r"start must have shape \(12, 12\)"):
        extend_tracks(tracks, lambda f: images[f], cams, acc, ref, DOTS, 0.05, 1.0, 3.0, start=acc[:, 1:])
    for bad in (0, 1.5, True):
        with pytest.raises(ValueError, match="min_run"):
            extend_tracks(tracks, lambda f: images[f], cams, acc, ref, DOTS, 0.05, 1.0, 3.0, min_run=bad)
    assert ReconstructSettings().walk_on is True
    with pytest.raises(ValueError, match="walk_on"):
        ReconstructSettings(walk_on=1)


def test_the_sentence():
    assert extend_line(None) is None
    assert "Walked 4 marker sighting(s)" in extend_line({"walks": 2, "walked": 4})
