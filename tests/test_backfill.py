"""A marker first seen after frame 0 is tracked back to the frames before (lipgen.recon.backfill)."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_images import background, frame
from test_firstframe import _layout
from test_raygap import _two_views

from lipgen.recon.backfill import WalkQueue, backfill, neighbour_motion, rewalk
from lipgen.recon.jumps import StepLimit
from lipgen.recon.track import LOST, MarkerTracker, TrackerSettings
from lipgen.recon.viewcheck import check_views

M, F = 5, 14


def _clip(fill: bool, lure: bool = False, seed: int = 4, queue: bool = False):
    """Two views of 12 marks (3 rows of 4, 7 mm apart) swaying together; mark M also slides
    0.3 mm a frame down, so its layout place (where it ends) is far from its dot early on and
    view 1 (which does not match it in the first frame) acquires it only once the dot comes
    within the gate. With ``lure``, M's dot is hidden in view 1 in frames 0-3 and a dot as dark
    as ink sits 4 px from it along the epipolar line (which runs along the rows) instead.
    Returns the (virtual, real) tracks, the true uv (2, F, P, 2) and each view's first
    acquisition frame of M."""
    cams = _two_views()
    rng = np.random.default_rng(seed)
    grid = np.array([(x, y, 0.0) for y in (-7.0, 0.0, 7.0) for x in (-10.5, -3.5, 3.5, 10.5)])
    t = np.arange(F)[:, None, None]
    marks = grid[None] + np.array([1.5, 1.0, 2.0]) * np.sin(0.3 * t)
    marks[:, M, 1] += 0.3 * (np.arange(F) - (F - 1))
    uv = np.stack([np.stack([c.project(m) for m in marks]) for c in cams])        # (2, F, P, 2)
    bases = [background((120, 160), rng) for _ in cams]
    trackers = []
    for v in range(2):
        init = uv[v, 0].copy()
        ref = uv[v, 0].copy()
        ref[M] = uv[v, -1, M] - (uv[v, -1] - uv[v, 0]).mean(0)      # M's place at the end
        if v == 1:
            init[M] = np.nan
        trackers.append(MarkerTracker(init, TrackerSettings(acquire_gate=6.0), reference_uv=ref))
    steps, last3d, since = StepLimit(12, 4.0), np.full((12, 3), np.nan), np.ones(12)
    walks = WalkQueue(12, 3)
    ever = None
    for f in range(F):
        for v in range(2):
            pts, shown = uv[v, f], np.ones(12, dtype=bool)
            if lure and v == 1 and f <= 3:
                shown = np.r_[shown, True]
                shown[M] = False
                pts = np.vstack([pts, pts[M] + [4.0, 0.0]])
            trackers[v].step(frame(bases[v], pts, rng, visible=shown))
        if f > 0:
            check_views(trackers, cams, 1.0, last3d, steps, since)
        seen = np.stack([tr._out[-1][1] != LOST for tr in trackers])
        if ever is None:
            ever = seen
        elif fill and queue:
            walks.step(trackers, cams, seen & ~ever, 1.0, steps, again=False)
        elif fill and (seen & ~ever).any():
            backfill(trackers, cams, seen & ~ever, 1.0, steps)
        ever |= seen
    tracks = [tr.tracks() for tr in trackers]
    return tracks, uv


def test_a_marker_missing_in_the_first_frame_gets_its_early_frames_back():
    tracks, uv = _clip(fill=False)
    first = int(np.flatnonzero(tracks[1].visible[:, M])[0])
    assert first >= 3, "acquired late: the layout is far from the dot early on"
    assert tracks[0].visible[:, M].all()
    filled, _ = _clip(fill=True)
    tr = filled[1]
    assert tr.visible[:, M].all(), "every frame before the acquisition is filled back"
    err = np.linalg.norm(tr.uv[:, M] - uv[1, :, M], axis=1)
    assert err.max() < 0.5
    others = np.delete(np.arange(12), M)
    # Equal up to rounding (two identical runs may round differently; see test_recheck).
    np.testing.assert_allclose(tr.uv[:, others], tracks[1].uv[:, others], rtol=0, atol=1e-7)


def test_the_queued_walk_waits_for_three_frames_in_both_views_and_fills_the_same():
    direct, _ = _clip(fill=True)
    queued, _ = _clip(fill=True, queue=True)
    for v in range(2):
        np.testing.assert_allclose(queued[v].uv, direct[v].uv, rtol=0, atol=1e-7)
    with pytest.raises(ValueError, match="frames must be at least 1, got 0"):
        WalkQueue(12, 0)


def test_a_lure_on_the_epipolar_line_before_the_first_sighting_is_not_filled():
    tracks, uv = _clip(fill=True, lure=True)
    tr = tracks[1]
    assert not tr.visible[:4, M].any(), "the lure 4 px along the epipolar line is refused"
    assert tr.visible[4:, M].all()
    err = np.linalg.norm(tr.uv[4:, M] - uv[1, 4:, M], axis=1)
    assert err.max() < 0.5


def test_neighbour_motion_is_the_weighted_mean_offset_and_none_without_neighbours():
    ref = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [50.0, 50.0]])
    a = ref.copy()
    b = a + [[0.0, 0.0], [2.0, 1.0], [2.0, 1.0], [2.0, 1.0]]
    np.testing.assert_allclose(neighbour_motion(ref, a, b, np.ones(4, dtype=bool), 0), [2.0, 1.0])
    assert neighbour_motion(ref, a, b, np.array([True, False, False, False]), 0) is None


def test_a_lure_pair_followed_before_a_loss_is_replaced_by_the_later_track():
    # Both views start on a lure pair: dots 2 mm off mark L's surface point (so the rays meet),
    # moving with it, until frame 5, when they vanish and the trackers find L's own dots. Walking
    # back from there (rewalk) replaces the lure's sightings by L's own dots.
    cams = _two_views()
    model = _layout()
    L, n = 4, 10
    rng = np.random.default_rng(3)
    t = np.arange(n)[:, None, None]
    marks = model[None] + [0.0, 0.0, 3.0] + np.array([1.0, 0.8, 1.5]) * np.sin(0.3 * t)
    lure3d = marks[:, L] + [0.0, 2.0, 0.0]
    uv = np.stack([np.stack([c.project(m) for m in marks]) for c in cams])
    lures = np.stack([c.project(lure3d) for c in cams])                        # (2, F, 2)
    bases = [background((120, 160), rng) for _ in cams]
    ref = [c.project(model) for c in cams]
    results = {}
    for walk in (False, True):
        trackers = []
        for v in range(2):
            init = uv[v, 0].copy()
            init[L] = lures[v, 0]
            trackers.append(MarkerTracker(init, TrackerSettings(acquire_gate=6.0), reference_uv=ref[v]))
        P = len(model)
        steps, last3d, since = StepLimit(P, 4.0), np.full((P, 3), np.nan), np.ones(P)
        for f in range(n):
            for v in range(2):
                pts = uv[v, f] if f >= 5 else np.vstack([uv[v, f], lures[v, f][None]])
                trackers[v].step(frame(bases[v], pts, rng))
            if f > 0:
                check_views(trackers, cams, 1.0, last3d, steps, since)
                if walk:
                    rewalk(trackers, cams, np.zeros(len(model), dtype=bool), 1.0, steps)
        results[walk] = [tr.tracks() for tr in trackers]
    for v in range(2):
        before = np.linalg.norm(results[False][v].uv[:5, L] - uv[v, :5, L], axis=1)
        assert np.all(before > 5.0), "without the walk the lure's sightings stay"
        tr = results[True][v]
        err = np.linalg.norm(tr.uv[:, L] - uv[v, :, L], axis=1)
        assert tr.visible[:, L].all() and err.max() < 0.5
