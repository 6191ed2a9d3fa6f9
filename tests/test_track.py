"""Dot detection and marker tracking on synthetic images with known dot centres."""

import numpy as np
import pytest
from synthetic_images import background, draw_dots, frame, marker_paths

from lipgen.recon.dots import DotSettings, as_gray, detect_dots, dot_peaks
from lipgen.recon.pointreg import match_to_expected
from lipgen.recon.track import (
    CORRELATION_ONLY,
    LOST,
    RECOVERED,
    TRACKED,
    TrackerSettings,
    normalized_correlation,
    track_markers,
)

SHAPE = (120, 160)


def _nearest_error(found, truth):
    d = np.linalg.norm(found[:, None] - truth[None], axis=2)
    return found[d.argmin(0)] - truth, d.min(0)


def _rms(err):
    return float(np.sqrt(np.nanmean((err ** 2).sum(-1))))


def test_detection_is_subpixel_on_plain_shading():
    rng = np.random.default_rng(1)
    flat = background(SHAPE, rng, texture=0.0)
    errs = []
    for _ in range(4):
        truth = marker_paths(1, 12, rng, SHAPE)[0]
        uv, strength = detect_dots(frame(flat, truth, rng, noise=0.01))
        assert len(uv) == 12, "every dot found and nothing else"
        assert np.all(strength > 0.1)
        err, _ = _nearest_error(uv, truth)
        errs.append(err)
    assert _rms(np.concatenate(errs)) < 0.06


def test_detection_is_subpixel_on_textured_skin():
    rng = np.random.default_rng(2)
    errs = []
    for _ in range(4):
        truth = marker_paths(1, 12, rng, SHAPE)[0]
        uv, _ = detect_dots(frame(background(SHAPE, rng), truth, rng, noise=0.01))
        err, dist = _nearest_error(uv, truth)
        assert np.all(dist < 0.6), "each true dot has a detection within 0.6 px"
        errs.append(err)
    assert _rms(np.concatenate(errs)) < 0.25


def test_detection_handles_colour_and_dot_size():
    rng = np.random.default_rng(3)
    truth = marker_paths(1, 6, rng, SHAPE, spacing=24)[0]
    grey = frame(background(SHAPE, rng, texture=0.0), truth, rng, sigma=3.0)
    rgb = np.repeat(grey[..., None], 3, axis=2)
    uv, _ = detect_dots(rgb, DotSettings(sigma=3.0))
    err, _ = _nearest_error(uv, truth)
    assert len(uv) == 6 and _rms(err) < 0.1
    with pytest.raises(ValueError, match=r"shape \(h, w\) or \(h, w, 3\|4\), got \(2, 3, 5\)"):
        as_gray(np.zeros((2, 3, 5)))
    with pytest.raises(ValueError, match="sigma"):
        DotSettings(sigma=0.0)


def test_normalized_correlation_closed_forms():
    rng = np.random.default_rng(4)
    search = rng.random((20, 24))
    tpl = search[5:12, 8:15].copy()
    ncc = normalized_correlation(search, tpl)
    assert ncc.shape == (14, 18)
    assert ncc[5, 8] == pytest.approx(1.0, abs=1e-12)
    assert np.unravel_index(ncc.argmax(), ncc.shape) == (5, 8)
    # Invariant to gain and offset; a negated template scores -1.
    assert normalized_correlation(search, 3 * tpl + 2)[5, 8] == pytest.approx(1.0, abs=1e-12)
    assert normalized_correlation(search, -tpl)[5, 8] == pytest.approx(-1.0, abs=1e-12)
    # Against a direct evaluation of the definition.
    win = search[2:9, 11:18]
    a, b = win - win.mean(), tpl - tpl.mean()
    assert ncc[2, 11] == pytest.approx((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum()), abs=1e-12)
    assert np.all(normalized_correlation(np.ones((10, 10)), tpl) == 0.0), "flat search scores 0"


def test_first_frame_matching_recovers_identity_under_similarity_and_clutter():
    rng = np.random.default_rng(5)
    layout = marker_paths(1, 16, rng, SHAPE)[0]
    ang = np.deg2rad(12)
    R = np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
    moved = 1.1 * (layout - layout.mean(0)) @ R.T + layout.mean(0) + [9.0, -6.0]
    moved += rng.normal(0, 0.8, moved.shape)
    clutter = rng.uniform([0, 0], [160, 120], (4, 2))
    clutter = clutter[np.linalg.norm(clutter[:, None] - moved[None], axis=2).min(1) > 6]
    perm = rng.permutation(16 + len(clutter))
    dots = np.concatenate([moved, clutter])[perm]
    match = match_to_expected(np.delete(dots, np.flatnonzero(perm == 3), axis=0), layout, gate=3.0)
    dots_wo = np.delete(perm, np.flatnonzero(perm == 3))
    assert match[3] == -1, "a marker with no dot stays unmatched"
    got = dots_wo[match[np.arange(16) != 3]]
    assert np.array_equal(got, np.delete(np.arange(16), 3))


def _sequence(n_frames=24, n_markers=12, seed=6, **kw):
    rng = np.random.default_rng(seed)
    base = background(SHAPE, rng)
    paths = marker_paths(n_frames, n_markers, rng, SHAPE, **kw)
    return rng, base, paths


def test_tracking_follows_known_paths_subpixel():
    rng, base, paths = _sequence()
    frames = [frame(base, p, rng) for p in paths]
    tracks = track_markers(frames, paths[0] + rng.normal(0, 0.5, paths[0].shape))
    assert tracks.uv.shape == paths.shape and tracks.visible.all()
    assert np.all(tracks.status == TRACKED)
    assert _rms(tracks.uv - paths) < 0.25
    assert np.nanmin(tracks.score[1:]) > 0.8


def test_occluded_marker_is_lost_then_recovered():
    rng, base, paths = _sequence(seed=7)
    hidden = np.ones(paths.shape[:2], dtype=bool)
    hidden[8:13, 4] = False
    frames = [frame(base, p, rng, visible=v) for p, v in zip(paths, hidden, strict=True)]
    tracks = track_markers(frames, paths[0])
    assert not tracks.visible[8:13, 4].any() and np.all(tracks.status[8:13, 4] == LOST)
    assert np.isnan(tracks.uv[8:13, 4]).all()
    assert tracks.visible[13:].all() and tracks.visible[:8].all()
    assert np.nanmax(np.linalg.norm(tracks.uv - paths, axis=2)) < 0.8


def test_recovery_after_a_sudden_jump_beyond_the_search_window():
    # From frame 10 the whole face jumps by 30 px (farther than the correlation search window
    # and more than two dot spacings): correlation alone would fail or lock onto a neighbour.
    rng, base, paths = _sequence(seed=8, amplitude=3.0)
    paths[10:] += np.array([30.0, -14.0])
    paths = paths[:, :, :] - np.array([15.0, -7.0])
    frames = [frame(base, p, rng) for p in paths]
    tracks = track_markers(frames, paths[0])
    assert tracks.visible.all()
    assert np.nanmax(np.linalg.norm(tracks.uv - paths, axis=2)) < 0.8


def test_marker_missing_in_first_frame_is_acquired_from_the_layout():
    rng, base, paths = _sequence(seed=9)
    shown = np.ones(paths.shape[:2], dtype=bool)
    shown[:5, 2] = False
    frames = [frame(base, p, rng, visible=v) for p, v in zip(paths, shown, strict=True)]
    init = paths[0].copy()
    init[2] = np.nan
    tracks = track_markers(frames, init, reference_uv=paths[0])
    assert not tracks.visible[:5, 2].any()
    assert tracks.visible[5:, 2].all() and tracks.status[5, 2] in (RECOVERED, TRACKED)
    assert np.nanmax(np.linalg.norm(tracks.uv[5:] - paths[5:], axis=2)) < 0.8


def test_status_codes_are_distinct_and_tracks_validate():
    assert len({TRACKED, RECOVERED, CORRELATION_ONLY, LOST}) == 4
    with pytest.raises(ValueError, match=r"initial_uv must have shape \(\*, 2\)"):
        track_markers([np.zeros(SHAPE)], np.zeros((3, 3)))
    with pytest.raises(ValueError, match="no frames"):
        track_markers([], np.zeros((3, 2)))


def test_swapped_neighbours_are_put_back_by_the_layout():
    # Two markers 5 px apart start swapped (as a first-frame match can leave them); the
    # reference layout says which is left of which, and the tracker restores the order.
    rng, base, paths = _sequence(seed=10, n_markers=6, spacing=22)
    paths[:, 1] = paths[:, 0] + np.array([5.0, 0.0])
    frames = [frame(base, p, rng, sigma=1.2) for p in paths]
    init = paths[0].copy()
    init[[0, 1]] = init[[1, 0]]
    tracks = track_markers(frames, init, TrackerSettings(dots=DotSettings(sigma=1.2)), reference_uv=paths[0])
    seen = tracks.visible[:, :2]
    assert seen.mean() > 0.9
    err = np.linalg.norm(tracks.uv[:, :2] - paths[:, :2], axis=2)
    assert np.nanmax(err) < 1.0


def _ellipse(img, uv, sx, sy, depth):
    yy, xx = np.mgrid[0:img.shape[0], 0:img.shape[1]]
    return img - depth * np.exp(-0.5 * (((xx - uv[0]) / sx) ** 2 + ((yy - uv[1]) / sy) ** 2))


def _corner_clip(seed, n_frames=24, onset=8):
    """The lip-corner failure in small: marker 0's dot turns away from the camera from frame
    ``onset`` (foreshortened over four frames into an ellipse the roundness test rejects), while a
    round dark blob that is no marker (the end of the mouth opening) sits 6 px beside it."""
    rng = np.random.default_rng(seed)
    base = background(SHAPE, rng)
    paths = marker_paths(n_frames, 6, rng, SHAPE, spacing=22, amplitude=3.0)
    frames = []
    for t, p in enumerate(paths):
        k = np.clip((t - onset) / 4, 0, 1)
        img = draw_dots(base, p[1:], sigma=1.5)
        img = _ellipse(img, p[0], 1.5 + 0.8 * k, 1.5 - 1.0 * k, 0.35 + 0.3 * k)
        img = _ellipse(img, p[0] + [6.0, 1.0], 1.5, 1.5, 0.45)
        img = img + 0.01 * rng.standard_normal(SHAPE)
        frames.append(np.clip(np.round(img * 255), 0, 255).astype(np.uint8))
    return frames, paths


def test_foreshortened_dot_is_a_candidate_but_not_a_detection():
    frames, paths = _corner_clip(11)
    gray = as_gray(frames[-1])
    uv, _ = detect_dots(gray)
    assert np.linalg.norm(uv - paths[-1, 0], axis=1).min() > 5, "the round-dot detector misses it"
    peaks, _, roundness = dot_peaks(gray, DotSettings())
    d = np.linalg.norm(peaks - paths[-1, 0], axis=1)
    assert d.min() < 1.5
    assert DotSettings().min_foreshortened_roundness <= roundness[d.argmin()] < DotSettings().min_roundness


def test_foreshortened_dots_near_the_centres_only_and_nothing_from_nothing():
    from lipgen.recon.blobs import foreshortened_dots, near_centres

    frames, paths = _corner_clip(11)
    gray = as_gray(frames[-1])
    settings = DotSettings()
    peaks, _, roundness = dot_peaks(gray, settings)
    elongated = peaks[roundness < settings.min_roundness]
    dots = detect_dots(gray)[0]
    target = paths[-1, 0]
    uv, idx = foreshortened_dots(gray, dots, elongated, target[None], np.array([3.0]), settings)
    assert len(uv) == 1 and np.linalg.norm(uv[0] - target) < 1.0   # sub-pixel, on the oblique dot
    assert np.linalg.norm(elongated[idx[0]] - target) <= 4.0
    far, _ = foreshortened_dots(gray, dots, elongated, target[None] + 40.0, np.array([3.0]), settings)
    assert len(far) == 0
    for empty in ((dots, elongated[:0], target[None]), (dots, elongated, np.zeros((0, 2))),
                  (dots[:0], elongated[:0], np.zeros((0, 2)))):
        uv, idx = foreshortened_dots(gray, *empty, np.full(len(empty[2]), 3.0), settings)
        assert uv.shape == (0, 2) and idx.shape == (0,) and idx.dtype == np.int64
    assert near_centres(np.zeros((0, 2)), target[None], np.array([1.0])).shape == (0,)
    assert not near_centres(target[None], np.zeros((0, 2)), np.zeros(0)).any()
    assert near_centres(np.array([[0.0, 0.0], [3.0, 4.0]]), np.array([[0.0, 0.0]]), np.array([5.0])).all()


@pytest.mark.parametrize("seed", [11, 14])
def test_foreshortened_dot_beside_a_round_blob_is_not_swapped_for_it(seed):
    # Before the fix the tracker, finding no round dot at its correlation peak, took the round
    # blob 6 px away and followed it for the rest of the clip (errors of 6 px on every frame).
    frames, paths = _corner_clip(seed)
    tracks = track_markers(frames, paths[0])
    err = np.linalg.norm(tracks.uv - paths, axis=2)
    seen = tracks.visible
    assert np.all(err[seen] < 1.0), "never on the blob: tracked correctly or reported lost"
    assert seen[:, 0].mean() > 0.8 and seen[:, 1:].all()


def test_reject_takes_a_sighting_back_and_the_marker_is_reacquired():
    from lipgen.recon.track import MarkerTracker
    rng, base, paths = _sequence(n_frames=12, n_markers=6, seed=12)
    tracker = MarkerTracker(paths[0])
    for t, p in enumerate(paths):
        tracker.step(frame(base, p, rng))
        if t == 5:
            assert not tracker.reacquired.any()
            tracker.reject([2])
    tracks = tracker.tracks()
    assert tracks.status[5, 2] == LOST and np.isnan(tracks.uv[5, 2]).all()
    assert tracks.visible[6:].all() and tracks.visible[:5].all()
    assert np.nanmax(np.linalg.norm(tracks.uv - paths, axis=2)) < 0.8


def test_a_sighting_the_other_view_contradicts_is_taken_back():
    # Two calibrated views of six 3-D marks. From frame 6 mark 0's dot is hidden in view 1 and a
    # round blob 6 px above it (off the epipolar line) takes its place; alone, that view's
    # tracker follows the blob. Checked against view 0, the sighting is refused instead.
    from lipgen.recon.track import MarkerTracker
    from lipgen.recon.viewcheck import check_views as _check_views
    from lipgen.rig.pinhole import PinholeCamera
    K = np.array([[400.0, 0, 80], [0, 400.0, 60], [0, 0, 1]])
    a = np.deg2rad(20)
    Ry = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    cams = (PinholeCamera(K, np.eye(3), np.array([0, 0, 300.0]), 160, 120),
            PinholeCamera(K, Ry, np.array([0, 0, 300.0]), 160, 120))
    rng = np.random.default_rng(13)
    grid = np.array([(x, y, 0.0) for y in (-6.0, 6.0) for x in (-12.0, 0.0, 12.0)])
    t = np.arange(14)[:, None, None]
    marks = grid[None] + np.array([2.0, 1.0, 3.0]) * np.sin(0.3 * t)
    uv = np.stack([np.stack([c.project(m) for m in marks]) for c in cams])        # (2, F, P, 2)
    bases = [background((120, 160), rng) for _ in cams]
    for check in (False, True):
        trackers = [MarkerTracker(uv[v, 0]) for v in range(2)]
        for f in range(len(marks)):
            for v in range(2):
                img_uv, shown = uv[v, f].copy(), np.ones(6, dtype=bool)
                if v == 1 and f >= 6:
                    shown[0] = False
                    img_uv = np.vstack([img_uv, img_uv[0] + [0.0, -6.0]])
                    shown = np.r_[shown, True]
                trackers[v].step(frame(bases[v], img_uv, rng, visible=shown))
            if check and f > 0:
                _check_views(trackers, cams, 2.0)
        err = np.linalg.norm(trackers[1].tracks().uv[6:, 0] - uv[1, 6:, 0], axis=1)
        if not check:
            assert np.nanmin(err) > 4, "alone, the view follows the blob"
        else:
            assert not trackers[1].tracks().visible[6:, 0].any(), "checked, the mark is reported lost"
            for v in range(2):
                tr = trackers[v].tracks()
                assert np.all(np.linalg.norm(tr.uv - uv[v], axis=2)[tr.visible] < 1.0)


def _row_drop(seed, drop, n_frames=12, at=6):
    """A 3 x 5 grid whose bottom row (markers 10-14) drops by ``drop`` px (one per marker, or
    one for all) at frame ``at`` while the rest stays: the lower lip opening, in small."""
    rng = np.random.default_rng(seed)
    base = background(SHAPE, rng)
    paths = marker_paths(n_frames, 15, rng, SHAPE, spacing=16, amplitude=2.0, own=0.5)
    paths[at:, 10:, 1] += np.asarray(drop, dtype=float)
    return rng, base, paths


@pytest.mark.parametrize("seed", [0, 5])
def test_lost_markers_follow_their_group_after_a_sudden_jump(seed):
    # The bottom row drops 11 px at frame 6 (the correlation follows) and two of its markers are
    # taken back there (as when the other view contradicts a wrong dot). Before, they came back
    # 11 px from where they were last seen, too far and too near their neighbours for the
    # unambiguous recovery (and the correlation found the bare skin where their dots had been),
    # and stayed lost. Carried with the row's markers seen dropping, they are re-acquired in the
    # next frame, all on their dots.
    # Without the curvature blobs (on by default since xc27): with them, seeds 0-3 and 6 lose one or two
    # markers to the end here. The skin's texture blobs, too faint for any marker to take, stand as rivals
    # of the real dots; dropping them fixed this but lost on rendered sets, where that caution keeps markers
    # off their neighbours' dots (renders/examples/tracking/faint28.md).
    from lipgen.recon.track import MarkerTracker, TrackerSettings
    rng, base, paths = _row_drop(seed, 11.0)
    tracker = MarkerTracker(paths[0], TrackerSettings(blobs=False), reference_uv=paths[0])
    for t, p in enumerate(paths):
        tracker.step(frame(base, p, rng))
        if t == 6:
            tracker.reject([12, 13])
    tracks = tracker.tracks()
    assert tracks.visible[7:].all() and tracks.visible[:6].all()
    assert np.nanmax(np.linalg.norm(tracks.uv - paths, axis=2)) < 0.8


def test_a_group_jumping_beyond_the_search_is_reacquired_at_once():
    # 20 px: beyond the correlation's reach and the recovery gate, and more than a row spacing.
    # Before, the whole row was lost for the rest of the clip (nothing near its predictions,
    # and no neighbour seen moving with it).
    rng, base, paths = _row_drop(1, 20.0)
    tracks = track_markers([frame(base, p, rng) for p in paths], paths[0], reference_uv=paths[0])
    assert tracks.visible.all()
    assert np.nanmax(np.linalg.norm(tracks.uv - paths, axis=2)) < 0.8


def test_a_group_that_did_not_move_as_one_is_not_shifted_onto_look_alike_dots():
    # A row dropping unevenly fits no single shift; shifted by one dot spacing it would put three
    # of its five markers on their neighbours' dots. Lost is fine, a wrong dot is not.
    for seed in range(4):
        rng, base, paths = _row_drop(seed, [12.0, 16.0, 20.0, 16.0, 12.0])
        tracks = track_markers([frame(base, p, rng) for p in paths], paths[0], reference_uv=paths[0])
        err = np.linalg.norm(tracks.uv - paths, axis=2)
        assert np.all(err[tracks.visible] < 1.0) and tracks.visible[:, :10].all()


def test_shift_group_moves_only_a_group_that_moved_as_one():
    from lipgen.recon.association import shift_group
    grid = np.array([(16.0 * c, 16.0 * r) for r in range(3) for c in range(5)]) + 20.0
    dots = grid.copy()
    dots[10:, 1] += 20.0                                   # the bottom row dropped together
    pred, moved = shift_group(grid, dots, gate=8.0, tol=3.0, reach=24.0)
    assert np.array_equal(moved, np.arange(15) >= 10)
    assert np.allclose(pred, dots)
    dots[10:, 1] = grid[10:, 1] + [12.0, 16.0, 20.0, 16.0, 12.0]     # unevenly: no one shift
    pred, moved = shift_group(grid, dots, gate=8.0, tol=3.0, reach=24.0)
    assert not moved.any() and np.array_equal(pred, grid)


def _faint_view(floor_ratio, seed=4, n_frames=6):
    """One view of 12 marks whose dots are all pale (peak 0.11, their smoothed darkness about 0.09,
    near the 0.08 floor), mark 5's paler still (0.075: under the floor) and not matched in the
    first frame, as on ``hard`` 25's mirror. Returns the tracks and the true uv (F, P, 2)."""
    rng = np.random.default_rng(seed)
    grid = np.array([(x, y) for y in (-7.0, 0.0, 7.0) for x in (-10.5, -3.5, 3.5, 10.5)]) * 2.5 + [80.0, 60.0]
    base = background(SHAPE, rng, texture=0.03)
    init = grid.copy()
    init[5] = np.nan
    settings = TrackerSettings(dots=DotSettings(sigma=1.5), acquire_gate=6.0, confident_correlation=1.0,
                               floor_ratio=floor_ratio)
    uv = grid[None] + np.array([0.7, 0.3]) * np.arange(n_frames)[:, None, None]
    frames = []
    for f in range(n_frames):
        img = draw_dots(base, np.delete(uv[f], 5, 0), depth=0.11)
        img = draw_dots(img, uv[f, 5][None], depth=0.075) + 0.004 * rng.standard_normal(SHAPE)
        frames.append(np.clip(np.round(img * 255), 0, 255).astype(np.uint8))
    return track_markers(frames, init, settings, grid), uv


def test_a_floor_from_the_views_own_dots_finds_a_dot_under_the_fixed_floor():
    tracks, uv = _faint_view(None)
    assert not tracks.visible[:, 5].any(), "under the fixed floor the pale dot is never acquired"
    tracks, uv = _faint_view(TrackerSettings().floor_ratio, n_frames=8)   # the default, 0.7
    assert tracks.visible[5:, 5].all()   # from frame 5 (at 0.5: from frame 3)
    err = np.linalg.norm(tracks.uv - uv, axis=2)
    assert err[tracks.visible].max() < 0.5
    assert tracks.visible[:, np.arange(12) != 5].all(), "the other marks are all tracked"


def test_the_floor_is_lowered_only_under_the_fixed_one():
    s = TrackerSettings(dots=DotSettings(min_contrast=0.08), floor_ratio=0.7)
    assert s.dots_for(0.2) is s.dots                      # 0.14 > 0.08: the fixed floor
    assert s.dots_for(0.1).min_contrast == pytest.approx(0.07)
    assert s.dots_for(np.nan) is s.dots                   # nothing known yet
    assert s.dots_for(0.08 / 0.7).min_contrast == pytest.approx(0.08)   # the boundary
    assert s.dots_for(0.06).min_contrast == pytest.approx(0.05)        # 0.042: held at floor_min
    assert s.dots_for(1e-6).min_contrast == pytest.approx(0.05)
    assert TrackerSettings(floor_min=0.0).dots_for(0.06).min_contrast == pytest.approx(0.042)
    for bad in (-0.01, 0.09, float("nan")):
        with pytest.raises(ValueError, match="floor_min"):
            TrackerSettings(dots=DotSettings(min_contrast=0.08), floor_min=bad)
    fixed = TrackerSettings(floor_ratio=None)
    assert fixed.dots_for(0.01) is fixed.dots
    assert TrackerSettings().floor_ratio == 0.7                     # on by default
    for bad in (0.0, 1.0, float("nan")):
        with pytest.raises(ValueError, match="floor_ratio"):
            TrackerSettings(floor_ratio=bad)
