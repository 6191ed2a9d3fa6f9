"""Markers seen in one view only, paired with the other view's dot where the 3-D layout puts them
(:mod:`lipgen.recon.oneview`), and the acquisition's darkness limit (``max_strength_ratio``)."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_images import background, draw_dots, frame, swaying_views
from test_raygap import _two_views

from lipgen.recon.oneview import confirmed_runs, pair_one_view
from lipgen.recon.pending import PendingAcquisitions
from lipgen.recon.track import LOST, MarkerTracker, TrackerSettings
from lipgen.recon.viewcheck import check_views

M, N, F = 5, 9, 10
GRID = np.array([(x, y, 0.0) for y in (-7.0, 0.0, 7.0) for x in (-10.5, -3.5, 3.5, 10.5)])


def _clip(pairing: bool, lure: bool = False, slid: bool = False, seed: int = 3):
    """Two views of 12 marks (3 rows of 4, 7 mm apart) swaying together; mark M is matched in
    neither view's first frame, and view 0 acquires it at frame 1.

    With ``lure``, view 1 also shows an ink blob 5 px below M's dot (off the epipolar line, which
    runs along the rows), and view 1's layout puts M halfway between the two: view 1's own
    acquisition refuses both as ambiguous. Mark N (7 mm below M) is hidden in view 0 in every
    clip, so view 1's track of it is never confirmed: on its own dot it must stay. With ``slid``,
    view 1's first-frame match of N sits on M's dot instead (N's own dot hidden there too).
    Returns the (virtual, real) tracks and the true uv (2, F, P, 2)."""
    cams = _two_views()
    rng = np.random.default_rng(seed)
    uv, bases = swaying_views(cams, GRID, F, rng)  # uv (2, F, P, 2)
    trackers = []
    for v in range(2):
        init, ref = uv[v, 0].copy(), uv[v, 0].copy()
        init[M] = np.nan
        if v == 0:
            init[N] = np.nan
        if slid and v == 1:
            init[N] = uv[1, 0, M]
        if lure and v == 1:
            ref[M] += [0.0, 2.5]  # the layout puts M halfway between its dot and the blob
        trackers.append(MarkerTracker(init, TrackerSettings(acquire_gate=6.0), reference_uv=ref))
    pending = PendingAcquisitions(12, max_age=10)
    for f in range(F):
        images = []
        for v in range(2):
            pts, shown = uv[v, f], np.ones(12, dtype=bool)
            if v == 0:
                shown[N] = False
            if v == 1 and lure:
                pts, shown = np.vstack([pts, pts[M] + [0.0, 5.0]]), np.r_[shown, True]
            if v == 1 and slid:
                shown[N] = False
            images.append(frame(bases[v], pts, rng, visible=shown))
            trackers[v].step(images[v])
        if f > 0:
            if pairing:
                fresh = np.stack([tr.acquired for tr in trackers]) | (pending.since >= 0)
                pair_one_view(trackers, images, cams, GRID, 1.0, fresh)
            pending.step(trackers, cams, 1.0)
            check_views(trackers, cams, 1.0)
    return [tr.tracks() for tr in trackers], uv


def _err(tracks, uv, v, i):
    return np.linalg.norm(tracks[v].uv[:, i] - uv[v, :, i], axis=1)


def test_a_one_view_acquisition_takes_the_other_views_dot_on_its_epipolar_line():
    # View 1 cannot acquire M by its own 2-D rules (its dot and the blob below it are both near
    # where the layout puts it); the blob is off view 0's epipolar line, M's dot is on it.
    without, uv = _clip(pairing=False, lure=True)
    assert not without[1].visible[:, M].any(), "view 1 alone refuses the ambiguous pair of dots"
    tracks, uv = _clip(pairing=True, lure=True)
    both = tracks[0].visible[:, M] & tracks[1].visible[:, M]
    assert both[1:].all() and not both[0]
    for v in range(2):
        assert _err(tracks, uv, v, M)[1:].max() < 0.5
    # View 1's right one-view track of N (hidden in view 0) is never touched.
    assert tracks[1].visible[:, N].all() and _err(tracks, uv, 1, N).max() < 0.5
    assert not tracks[1].rejected[:, N].any()


def test_a_one_view_track_on_another_markers_dot_is_released_for_it():
    # View 1's N sits on M's dot from the first frame, a track view 0 never confirms (N is hidden
    # there). View 0's acquisition of M claims that dot along its epipolar line.
    without, uv = _clip(pairing=False, slid=True)
    assert not (without[0].visible[:, M] & without[1].visible[:, M]).any()
    assert without[1].visible[:, N].all(), "without the pairing N keeps M's dot"
    tracks, uv = _clip(pairing=True, slid=True)
    both = tracks[0].visible[:, M] & tracks[1].visible[:, M]
    assert both[1:].all()
    for v in range(2):
        assert _err(tracks, uv, v, M)[1:].max() < 0.5
    assert tracks[1].rejected[1, N] and not tracks[1].visible[1:, N].any(), "N released from frame 1"


def test_confirmed_runs_follow_each_views_current_run():
    trackers = [MarkerTracker(np.zeros((3, 2))) for _ in range(2)]
    # Frames: marker 0 seen in both views then in view 0 only; marker 1 seen only in view 0;
    # marker 2 seen in both, lost in view 0, seen again in view 0 only.
    seen = [np.array([[1, 1, 1], [1, 1, 0], [1, 1, 1]]), np.array([[1, 0, 1], [0, 0, 1], [0, 0, 0]])]
    for f in range(3):
        for v in range(2):
            status = np.where(seen[v][f] > 0, 0, LOST).astype(np.int8)
            trackers[v]._out.append((np.zeros((3, 2)), status, np.zeros(3)))
    got = confirmed_runs(trackers)
    assert got[0].tolist() == [True, False, False]
    assert got[1].tolist() == [False, False, False]


def test_an_acquisition_refuses_a_blob_far_darker_than_ink():
    # One view; mark M is not matched in the first frame, and where the layout puts it from
    # frame 1 on lies a blob about 3 times as dark as the marks' dots, not M's own dot (the
    # mouth's inside at a lip corner).
    rng = np.random.default_rng(4)
    uv = GRID[:, :2] * 2.5 + [80.0, 60.0]
    base = background((120, 160), rng)

    def run(max_ratio):
        init = uv.copy()
        init[M] = np.nan
        tr = MarkerTracker(init, TrackerSettings(acquire_gate=6.0, max_strength_ratio=max_ratio), uv)
        for f in range(4):
            shown = np.ones(12, dtype=bool)
            shown[M] = f == 0
            img = draw_dots(base, uv, depth=0.15, visible=shown)
            if f > 0:
                img = draw_dots(img, uv[M][None] + [1.0, 0.0], depth=0.8)
            img = img + 0.01 * rng.standard_normal(base.shape)
            tr.step(np.clip(np.round(img * 255), 0, 255).astype(np.uint8))
        return tr.tracks()

    assert run(None).visible[1:, M].all(), "without the limit the dark blob is taken"
    assert not run(2.0).visible[:, M].any()


def test_pairing_needs_enough_markers_seen_in_both_views():
    tracks = [MarkerTracker(np.zeros((12, 2)), reference_uv=np.zeros((12, 2))) for _ in range(2)]
    for tr in tracks:
        tr._out = [(np.full((12, 2), np.nan), np.full(12, LOST, dtype=np.int8), np.zeros(12))] * 2
    changed = pair_one_view(tracks, [None, None], _two_views(), GRID, 1.0)
    assert changed.shape == (2, 12) and not changed.any()
    with pytest.raises(ValueError, match="rest_points"):
        pair_one_view(tracks, [None, None], _two_views(), GRID[:5], 1.0)
    with pytest.raises(ValueError, match="fresh"):
        pair_one_view(tracks, [None, None], _two_views(), GRID, 1.0, np.ones((2, 5), dtype=bool))
    with pytest.raises(ValueError, match="ratio"):
        pair_one_view(tracks, [None, None], _two_views(), GRID, 1.0, ratio=1.5)


@pytest.mark.parametrize("bad", [0.0, -1.0, 0.4, float("nan")])
def test_a_darkness_limit_below_the_minimum_is_refused(bad):
    # 0 once meant "no limit" and a limit under min_strength_ratio refused every acquisition
    with pytest.raises(ValueError, match="max_strength_ratio.*" + ("nan" if bad != bad else repr(bad))):
        TrackerSettings(max_strength_ratio=bad)
    with pytest.raises(ValueError, match="min_strength_ratio"):
        TrackerSettings(min_strength_ratio=-0.1)
    assert TrackerSettings(max_strength_ratio=None).max_strength_ratio is None
