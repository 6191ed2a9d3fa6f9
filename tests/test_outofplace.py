"""The last pass over the tracks: pairs out of place in the 3-D layout (lipgen.recon.outofplace).

The 14-mark patch of tests/test_motioncheck.py sways before two views; its tracks are the true
projections plus 0.1 px of noise. From frame 4 mark BAD's view-1 sighting is a lure 8 mm along
view 0's ray: on the epipolar line, so the rays still meet, at a point 8 mm from the mark.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_firstframe import _lure_on_epipolar_line
from test_motioncheck import _layout, _marks
from test_raygap import _two_views

from lipgen.recon.outofplace import out_of_place, take_back_out_of_place
from lipgen.recon.track import LOST, TRACKED
from lipgen.recon.tracks import Tracks
from lipgen.rig.pinhole import triangulate

BAD = 3


def _tracks(lure_from=None, along=8.0):
    cams = _two_views()
    marks = _marks()
    rng = np.random.default_rng(3)
    uv = np.stack([np.stack([c.project(m) for m in marks]) for c in cams])
    uv = uv + 0.1 * rng.standard_normal(uv.shape)
    if lure_from is not None:
        for f in range(lure_from, len(marks)):
            uv[1, f, BAD] = _lure_on_epipolar_line(cams, marks[f, BAD], along)
    F, P = uv.shape[1:3]
    status = np.full((F, P), TRACKED, dtype=np.int8)
    tracks = tuple(
        Tracks(
            uv[v].copy(),
            np.ones((F, P), dtype=bool),
            status.copy(),
            np.full((F, P), np.nan),
            np.zeros((F, P), dtype=bool),
        )
        for v in range(2)
    )
    return tracks, cams, marks


def test_a_pair_on_the_epipolar_line_8mm_off_is_taken_back_and_nothing_else():
    tracks, cams, marks = _tracks(lure_from=4)
    gap = triangulate(cams[1], tracks[1].uv[4:, BAD], cams[0], tracks[0].uv[4:, BAD])[1]
    assert gap.max() < 0.1, "the rays meet: the ray gap cannot see it"
    new, taken = take_back_out_of_place(tracks, cams, _layout())
    expected = np.zeros(taken.shape, dtype=bool)
    expected[4:, BAD] = True
    np.testing.assert_array_equal(taken, expected)
    for v in range(2):
        assert np.isnan(new[v].uv[4:, BAD]).all() and (new[v].status[4:, BAD] == LOST).all()
        assert new[v].rejected[4:, BAD].all() and not new[v].visible[4:, BAD].any()
        keep = ~expected
        np.testing.assert_array_equal(new[v].uv[keep], tracks[v].uv[keep])
        assert tracks[v].visible.all(), "the tracks given are not changed"


def test_right_tracks_and_a_lure_within_the_floor_are_left_alone():
    tracks, cams, _ = _tracks()
    assert not out_of_place(tracks, cams, _layout()).any()
    tracks, cams, _ = _tracks(lure_from=4, along=2.0)  # 2 mm along the ray: under the 3 mm floor
    assert not out_of_place(tracks, cams, _layout()).any()
    assert out_of_place(tracks, cams, _layout(), floor=1.0)[4:, BAD].all()


def test_frames_with_few_pairs_are_not_judged():
    tracks, cams, _ = _tracks(lure_from=4)
    vis = tracks[0].visible.copy()
    vis[:, 7:] = False  # 7 pairs left, under min_pairs = 8
    thin = (Tracks(tracks[0].uv, vis, tracks[0].status, tracks[0].score, tracks[0].rejected), tracks[1])
    assert not out_of_place(thin, cams, _layout()).any()
    assert out_of_place(thin, cams, _layout(), min_pairs=6)[4:, BAD].all()


def test_bad_arguments_are_refused():
    tracks, cams, _ = _tracks()
    with pytest.raises(ValueError, match=r"tracks must both have shape \(F, 5, 2\)"):
        out_of_place(tracks, cams, _layout()[:5])
    with pytest.raises(ValueError, match="k must be > 0 and floor >= 0"):
        out_of_place(tracks, cams, _layout(), k=0.0)
    with pytest.raises(ValueError, match="min_pairs must be an integer >= 6, got 5"):
        out_of_place(tracks, cams, _layout(), min_pairs=5)
