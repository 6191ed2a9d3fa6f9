"""A marker on a close neighbour's dot in both views (lipgen.recon.shifted).

The 14-mark patch of tests/test_motioncheck.py (two rows 6 mm apart, marks 5 mm apart in a row)
sways before two views; each frame's dots are the marks' projections plus 0.1 px of noise. As on
``hard`` 31, mark BAD's dot is too faint for one view, and the tracks hold BAD on its row
neighbour's dot in both views while the neighbour is lost: the rays meet at the neighbour's
point. BAD's own dot, free in the other view, tells the two readings apart.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_motioncheck import _layout, _marks
from test_raygap import _two_views

from lipgen.recon.shifted import ShiftCheck
from lipgen.recon.track import LOST, TRACKED
from lipgen.recon.tracks import Tracks

BAD, NB, FAR = 3, 4, 2  # lower row x = 0; its neighbours at x = +5 and x = -5 mm


def _check():
    """The patch's row neighbours are one layout spacing apart (like the lip corners' pairs, which
    the default reach of 0.9 spacings leaves out): checked here with a reach of 1.0."""
    return ShiftCheck(_layout(), reach=1.0)


def _scene(hidden=(), lost=(), on_neighbour=False, lure=None):
    """Tracks and per-frame dots. ``hidden``: (view, mark) dots not found; ``lost``: marks the tracks
    lost; ``on_neighbour``: BAD held on NB's dot in both views (NB lost); ``lure`` (3,): a point in
    the marks' frame (moving with them) whose dot both views find too."""
    cams = _two_views()
    rng = np.random.default_rng(4)
    uv = np.stack([np.stack([c.project(m) for m in _marks()]) for c in cams])
    uv = uv + 0.1 * rng.standard_normal(uv.shape)
    F, P = uv.shape[1:3]
    dots = [
        tuple(np.delete(uv[v, f], [i for w, i in hidden if w == v], axis=0) for v in range(2))
        for f in range(F)
    ]
    if lure is not None:
        shift = _marks()[:, BAD] - _layout()[BAD]
        extra = [c.project(lure + shift) for c in cams]
        dots = [tuple(np.vstack([d[v], extra[v][f]]) for v in range(2)) for f, d in enumerate(dots)]
    held = uv.copy()
    status = np.full((2, F, P), TRACKED, dtype=np.int8)
    if on_neighbour:
        held[:, :, BAD] = uv[:, :, NB]
        lost = (*lost, NB)
    for i in lost:
        held[:, :, i], status[:, :, i] = np.nan, LOST
    tracks = tuple(
        Tracks(held[v], status[v] != LOST, status[v], np.full((F, P), np.nan), np.zeros((F, P), dtype=bool))
        for v in range(2)
    )
    return tracks, dots, cams, uv


def test_a_marker_on_its_neighbours_dot_is_taken_back_where_its_own_dot_is_free():
    # BAD's dot is hidden in view 0 and free in view 1: read as NB's, the pair puts BAD 5 mm
    # along the row, on that free dot; read as BAD's, NB would sit 5 mm the other way, where
    # there is no free dot (FAR's dot is held).
    tracks, dots, cams, uv = _scene(hidden={(0, BAD)}, on_neighbour=True)
    new, taken = _check().take_back(tracks, dots, cams)
    expected = np.zeros(taken.shape, dtype=bool)
    expected[:, BAD] = True
    np.testing.assert_array_equal(taken, expected)
    for v in range(2):
        assert not new[v].visible[:, BAD].any() and new[v].rejected[:, BAD].all()
        assert np.isnan(new[v].uv[:, BAD]).all() and (new[v].status[:, BAD] == LOST).all()
        np.testing.assert_array_equal(new[v].uv[~expected], tracks[v].uv[~expected])
        assert tracks[v].visible[:, BAD].all(), "the tracks given are not changed"
    # Frames whose dots are no longer held are not read.
    dots[3] = None
    assert not _check().take_back(tracks, dots, cams)[1][3].any()
    # At the default reach, neighbours one spacing apart are not read.
    assert not ShiftCheck(_layout()).take_back(tracks, dots, cams)[1].any()


def test_a_right_marker_beside_a_lost_neighbour_is_left_alone():
    check = _check()
    # NB lost, its dot found and free: read as BAD's, BAD's dots put NB on it, even with a lure
    # 7.5 mm the other way, where reading them as NB's would put BAD.
    lure = _layout()[BAD] + 1.5 * (_layout()[BAD] - _layout()[NB])
    tracks, dots, cams, _ = _scene(lost=(NB,), lure=lure)
    assert not check.take_back(tracks, dots, cams)[1].any()
    # NB's dot hidden in both views and FAR lost too: FAR's free dot lies where reading BAD's dots
    # as NB's would put BAD, but it is where the layout puts FAR.
    tracks, dots, cams, _ = _scene(hidden={(0, NB), (1, NB)}, lost=(NB, FAR))
    assert not check.take_back(tracks, dots, cams)[1].any()
    # A marker shifted onto its neighbour while its own dot is found in neither view: no evidence.
    tracks, dots, cams, _ = _scene(hidden={(0, BAD), (1, BAD)}, on_neighbour=True)
    assert not check.take_back(tracks, dots, cams)[1].any()


def _lose_in_one_view(tracks, view, mark):
    """``tracks`` with ``mark`` lost in ``view`` only (seen in the other: not seen in both views)."""
    t = tracks[view]
    uv, visible, status = t.uv.copy(), t.visible.copy(), t.status.copy()
    uv[:, mark], visible[:, mark], status[:, mark] = np.nan, False, LOST
    one = Tracks(uv, visible, status, t.score, t.rejected)
    return (one, tracks[1]) if view == 0 else (tracks[0], one)


def test_a_neighbour_seen_in_one_view_only():
    check = _check()
    # NB right in view 1, its dot not found in view 0 (so NB is not seen in both views), BAD right:
    # NB's only dot is held, so no reading puts anyone on a free dot; BAD is left alone.
    tracks, dots, cams, _ = _scene(hidden={(0, NB)})
    tracks = _lose_in_one_view(tracks, 0, NB)
    assert not check.take_back(tracks, dots, cams)[1].any()
    # The same with NB's dot found and free in view 0: reading BAD's dots as BAD's puts NB on it.
    tracks, dots, cams, _ = _scene()
    tracks = _lose_in_one_view(tracks, 0, NB)
    assert not check.take_back(tracks, dots, cams)[1].any()
    # BAD on NB's dot in both views while NB holds that dot in view 1: BAD's own dot, free in view 1,
    # is where reading the pair as NB's puts BAD; taken back in both views, NB's sighting kept.
    tracks, dots, cams, uv = _scene(hidden={(0, BAD)})
    for v in range(2):
        tracks[v].uv[:, BAD] = uv[v, :, NB]
    tracks = _lose_in_one_view(tracks, 0, NB)
    new, taken = check.take_back(tracks, dots, cams)
    assert taken[:, BAD].all() and taken.sum() == taken.shape[0]
    np.testing.assert_array_equal(new[1].uv[:, NB], tracks[1].uv[:, NB])
    assert new[1].visible[:, NB].all() and not new[0].visible[:, BAD].any()


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match="rest_points"):
        ShiftCheck(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="ShiftCheck.reach must be a positive number, got 0"):
        ShiftCheck(_layout(), reach=0)
    with pytest.raises(ValueError, match="stretch > 1 and angle < 90 degrees, got 1.0, 30.0"):
        ShiftCheck(_layout(), stretch=1.0)
    with pytest.raises(ValueError, match="min_pairs must be an integer >= 4, got 3"):
        ShiftCheck(_layout(), min_pairs=3)
    tracks, dots, cams, _ = _scene()
    with pytest.raises(ValueError, match=r"dots F entries, got \(10, 14, 2\), \(10, 14, 2\) and 9"):
        ShiftCheck(_layout()).take_back(tracks, dots[:9], cams)


def _two_view_frames(n_frames=3):
    """A raw sequence of two swaying views side by side, for track_raw_frames."""
    from synthetic_images import frame, swaying_views

    cams = _two_views()
    rng = np.random.default_rng(4)
    X = np.array([(-8.0, -6.0, 0.0), (8.0, -6.0, 0.0), (-8.0, 6.0, 0.0), (8.0, 6.0, 0.0), (0.0, 0.0, 1.0)])
    uv, bases = swaying_views(cams, X, n_frames, rng)

    class TwoViews:  # the raw frame is the two views side by side
        @staticmethod
        def split_views(raw):
            return raw[:, :160], raw[:, 160:]

    raws = [np.hstack([frame(bases[v], uv[v, f], rng) for v in range(2)]) for f in range(n_frames)]
    return raws, TwoViews(), uv[:, 0], cams, X


def test_track_raw_frames_runs_both_passes_once_tracking_is_done_by_default(monkeypatch):
    import lipgen.recon.steps as steps
    from lipgen.recon.settings import ReconstructSettings

    raws, layout, expected, cams, X = _two_view_frames()
    calls = []

    class Recorded(ShiftCheck):
        def take_back(self, tracks, dots, cameras, names=None):
            calls.append(("shift", len(tracks[0].uv), [tuple(np.shape(d) for d in f) for f in dots]))
            return super().take_back(tracks, dots, cameras, names)

    real = steps.take_back_out_of_place
    monkeypatch.setattr(steps, "ShiftCheck", Recorded)
    monkeypatch.setattr(
        steps, "take_back_out_of_place", lambda *a, **kw: calls.append(("place", kw["k"])) or real(*a, **kw)
    )
    steps.track_raw_frames(iter(raws), layout, expected, ReconstructSettings(), cameras=cams, rest_points=X)
    assert [c[0] for c in calls] == ["shift", "place"] and calls[1][1] == ReconstructSettings().out_of_place_k
    F, shapes = calls[0][1], calls[0][2]
    assert F == len(raws) and len(shapes) == F, "every frame's dots, one entry per frame"
    assert all(len(s) == 2 and all(len(v) == 2 and v[1] == 2 for v in s) for s in shapes), shapes
    calls.clear()
    off = ReconstructSettings(shift_check=False, out_of_place_k=None)
    steps.track_raw_frames(iter(raws), layout, expected, off, cameras=cams, rest_points=X)
    assert calls == [], "off: neither pass runs"


@pytest.mark.parametrize("k", [0.0, -1.0, float("nan"), True, "2"])
def test_a_bad_out_of_place_k_is_refused_before_any_frame_is_read(k):
    import lipgen.recon.steps as steps
    from lipgen.recon.settings import ReconstructSettings

    raws, layout, expected, cams, X = _two_view_frames(1)
    read = []

    def frames():
        for raw in raws:
            read.append(1)
            yield raw

    with pytest.raises(ValueError, match=r"settings.out_of_place_k must be None \(off\) or a number > 0"):
        steps.track_raw_frames(
            frames(), layout, expected, ReconstructSettings(out_of_place_k=k), cameras=cams, rest_points=X
        )
    assert read == [], "refused before the work"
