"""Markers not matched in the first frame are acquired later, from the layout, and only where both
views agree (``TrackerSettings.acquire_gate``, :func:`lipgen.recon.viewcheck.check_views`)."""

from dataclasses import replace

import numpy as np
import pytest
from synthetic_images import background, frame
from test_raygap import _two_views

from lipgen.recon.acquire import acquire, place_layout
from lipgen.recon.pointreg import similarity_2d
from lipgen.recon.track import MarkerTracker, TrackerSettings
from lipgen.recon.viewcheck import check_views


def test_place_layout_is_exact_under_a_similarity_and_keeps_the_seen_markers():
    rng = np.random.default_rng(3)
    layout = rng.uniform(0, 100, (12, 2))
    a = np.deg2rad(17)
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    moved = 1.3 * layout @ R.T + [12.0, -5.0]
    seen = np.ones(12, dtype=bool)
    seen[[2, 7, 9]] = False
    uv = np.where(seen[:, None], moved, np.nan)
    np.testing.assert_allclose(place_layout(layout, uv, seen), moved, atol=1e-9)
    # a local bend of the seen markers near marker 2 moves its placement the same way
    bent = moved.copy()
    near = np.argsort(np.linalg.norm(layout - layout[2], axis=1))[1:4]
    near = near[seen[near]]
    bent[near] += [0.0, 3.0]
    got = place_layout(layout, np.where(seen[:, None], bent, np.nan), seen)
    assert 0.5 < got[2, 1] - moved[2, 1] < 3.0
    s, _, _ = similarity_2d(layout[seen], moved[seen])
    assert s == pytest.approx(1.3)
    with pytest.raises(ValueError, match="at least 3"):
        place_layout(layout, uv, np.arange(12) < 2)


def test_acquire_takes_only_free_unambiguous_dots_within_the_gate():
    aligned = np.array([[0.0, 0.0], [20.0, 0.0], [40.0, 0.0], [60.0, 0.0]])
    wanted = np.array([True, True, True, False])
    dots = np.array([[0.5, 0.0],            # marker 0's: clear
                     [21.0, 2.0], [19.0, -2.2],   # marker 1: two dots nearly as close: ambiguous
                     [47.0, 0.0],           # marker 2: beyond the gate of 6 px
                     [60.0, 0.3]])          # marker 3 is not wanted
    free = np.ones(len(dots), dtype=bool)
    got = acquire(aligned, dots, wanted, free, gate=6.0)
    assert got.tolist() == [0, -1, -1, -1]
    free[0] = False                         # taken by another marker already
    assert acquire(aligned, dots, wanted, free, gate=6.0)[0] == -1
    with pytest.raises(ValueError, match="wanted must have shape"):
        acquire(aligned, dots, wanted[:2], free, gate=6.0)


LATE, NEVER, APPEARS = 5, 6, 6


def _clip(settings, seed=4, n_frames=14):
    """Two views of 12 marks (3 rows of 4, 7 mm apart). Mark LATE's dot is absent in both views
    until frame APPEARS; mark NEVER's dot never shows. Lures (round dots as dark as ink, 5 px
    above or below, off the epipolar lines, which run along the rows) sit beside both marks in
    view 1 all along, and beside NEVER in view 0 too. Neither mark is matched in the first frame.
    Returns the (virtual, real) tracks, the true uv (2, F, P, 2) and the acquisitions made before
    the views were compared (2, F, P)."""
    cams = _two_views()
    rng = np.random.default_rng(seed)
    grid = np.array([(x, y, 0.0) for y in (-7.0, 0.0, 7.0) for x in (-10.5, -3.5, 3.5, 10.5)])
    t = np.arange(n_frames)[:, None, None]
    marks = grid[None] + np.array([1.5, 1.0, 2.0]) * np.sin(0.3 * t)
    uv = np.stack([np.stack([c.project(m) for m in marks]) for c in cams])        # (2, F, P, 2)
    bases = [background((120, 160), rng) for _ in cams]
    trackers, guesses = [], np.zeros((2, n_frames, 12), dtype=bool)
    for v in range(2):
        init = uv[v, 0].copy()
        init[[LATE, NEVER]] = np.nan
        trackers.append(MarkerTracker(init, settings, reference_uv=uv[v, 0]))
    lures = {0: [(NEVER, [0.0, -5.0])], 1: [(LATE, [0.0, 5.0]), (NEVER, [0.0, 5.0])]}
    for f in range(n_frames):
        for v in range(2):
            shown = np.ones(12, dtype=bool)
            shown[NEVER] = False
            shown[LATE] = f >= APPEARS
            extra = np.array([uv[v, f, i] + off for i, off in lures[v]])
            img = frame(bases[v], np.vstack([uv[v, f], extra]), rng,
                        visible=np.r_[shown, [True] * len(extra)])
            trackers[v].step(img)
            guesses[v, f] = trackers[v].acquired
        if f > 0:
            check_views(trackers, cams, 1.0)
    return [tr.tracks() for tr in trackers], uv, guesses


def test_a_marker_appearing_later_is_acquired_at_its_appearance_and_a_lure_never_is():
    tracks, uv, guesses = _clip(TrackerSettings(acquire_gate=6.0))
    assert guesses[1, 1:APPEARS, LATE].all() and guesses[:, 1:, NEVER].all(), "the lures were tried"
    for v in range(2):
        tr = tracks[v]
        assert not tr.visible[:APPEARS, LATE].any(), "the lure beside the absent dot is not taken"
        assert tr.visible[APPEARS:, LATE].all(), "acquired in the frame the dot appears"
        assert not tr.visible[:, NEVER].any(), "lures the two views disagree on are never taken"
        assert not tr.rejected[:, [LATE, NEVER]].any(), "a withdrawn guess is no rejected sighting"
        others = np.delete(np.arange(12), [LATE, NEVER])
        assert tr.visible[:, others].all()
        err = np.linalg.norm(tr.uv - uv[v], axis=2)
        assert np.all(err[tr.visible] < 1.0)


def test_without_the_layout_acquisition_the_lure_is_taken():
    # The route it replaces: a marker not seen yet placed by its neighbours' local offsets in the
    # motion prediction and taken like a lost marker, with no other view to confirm it.
    tracks, uv, _ = _clip(TrackerSettings(acquire_gate=None, blobs=False))   # (with the blobs it is not)
    err = np.linalg.norm(tracks[1].uv[:, LATE] - uv[1, :, LATE], axis=1)
    assert np.nanmax(err) > 3.0, "view 1 follows the lure beside the absent dot"


def test_acquisition_without_a_layout_or_when_switched_off_does_nothing():
    rng = np.random.default_rng(1)
    pts = np.array([[40.0, 40.0], [60.0, 40.0], [80.0, 40.0], [60.0, 60.0]])
    base = background((120, 160), rng)
    init = pts.copy()
    init[3] = np.nan
    on, off = TrackerSettings(acquire_gate=6.0), replace(TrackerSettings(), acquire_gate=None)
    for settings, ref in ((on, None), (off, pts)):
        tr = MarkerTracker(init, settings, reference_uv=ref)
        for _ in range(3):
            tr.step(frame(base, pts, rng))
            assert not tr.acquired.any()


def test_a_marker_lost_after_being_seen_is_reacquired_from_the_layout_only_with_reacquire_after():
    """Marker 4 is seen in frame 0 off its layout place, hidden in frames 1-2, and back in frame 3 at its
    layout place, 25 px from where it was lost: beyond every motion gate (recovery 8 + 3 per frame lost),
    so only the layout acquisition finds it, and by default that is for markers never seen."""
    rng = np.random.default_rng(4)
    layout = np.array([[40.0, 40.0], [70.0, 40.0], [100.0, 40.0], [40.0, 80.0], [70.0, 80.0], [100.0, 80.0]])
    start = layout.copy()
    start[4] += [0.0, 25.0]
    base = background((140, 160), rng)
    shown = np.ones(6, dtype=bool)
    images = [frame(base, start, rng)]
    shown[4] = False
    images += [frame(base, layout, rng, visible=shown) for _ in range(2)]
    images += [frame(base, layout, rng) for _ in range(4)]
    out = {}
    for after in (None, 1, 3):
        settings = TrackerSettings(acquire_gate=6.0, reacquire_after=after)
        tr = MarkerTracker(start, settings, reference_uv=layout)
        for image in images:
            tr.step(image)
        out[after] = tr.tracks()
    assert not out[None].visible[1:, 4].any(), "by default it stays lost"
    for after, back in ((1, 3), (3, 4)):   # 3: wanted once lost in 3 images (frames 1-3), taken in frame 4
        tracks = out[after]
        assert not tracks.visible[1:back, 4].any() and tracks.visible[back:, 4].all()
        assert np.linalg.norm(tracks.uv[back:, 4] - layout[4], axis=1).max() < 1.0
        others = np.delete(np.arange(6), 4)
        assert tracks.visible[:, others].all()
    for bad in (0, -1, 1.5, True, "2"):
        with pytest.raises(ValueError, match="reacquire_after must be None .* or an integer >= 1"):
            TrackerSettings(reacquire_after=bad)
