"""Blob peaks of the Laplacian (lipgen.recon.blobs) and the epipolar recovery that offers them."""

import numpy as np
import pytest
from synthetic_images import draw_dots, frame
from test_epipolar import six_marks

from lipgen.recon.blobs import blob_peaks
from lipgen.recon.dots import DotSettings, dot_peaks
from lipgen.recon.epipolar import recover_along_epipolar
from lipgen.recon.track import RECOVERED, MarkerTracker, TrackerSettings
from lipgen.recon.viewcheck import check_views


def _log(cfg):
    """``cfg`` with the Laplacian-of-Gaussian blob response these toy scenes were built for (the default is
    the curvature pit since xc27)."""
    from dataclasses import replace
    return replace(cfg, dots=replace(cfg.dots, blob_response="log"))


def _dot_by_a_line(gap: float, line_width: float = 2.5) -> np.ndarray:
    """(41, 61): a dot (sigma 1.5, relative depth 0.25) at (30 - gap, 20) beside a dark vertical line
    (relative depth 0.5, Gaussian profile of ``line_width``) along column 30, on a 0.7 background."""
    y, x = np.mgrid[:41, :61].astype(float)
    line = np.exp(-((x - 30) ** 2) / (2 * line_width ** 2))
    dot = np.exp(-((x - (30 - gap)) ** 2 + (y - 20) ** 2) / (2 * 1.5 ** 2))
    return 0.7 * (1 - 0.5 * line) * (1 - 0.25 * dot)


@pytest.mark.parametrize("gap", [5.0, 6.0])
def test_a_dot_on_a_dark_lines_flank_is_a_blob_but_no_top_hat_peak(gap):
    img = _dot_by_a_line(gap)
    uv, _, _ = dot_peaks(img, DotSettings(sigma=1.5, min_contrast=0.005, noise_k=0.0, blob_response="log"))
    assert len(uv) == 0 or np.linalg.norm(uv - [30 - gap, 20], axis=1).min() > 1.5
    b, strength = blob_peaks(img, DotSettings(sigma=1.5, blob_response="log"))
    assert len(b) == 1 and np.linalg.norm(b[0] - [30 - gap, 20]) <= 1.0
    assert 0.05 < strength[0] < 0.7 * 0.5        # the top-hat there: dark, not the line's depth


def test_blobs_by_a_peak_already_found_are_left_out():
    img = _dot_by_a_line(6.0)
    log = DotSettings(sigma=1.5, blob_response="log")
    assert len(blob_peaks(img, log, exclude=np.array([[25.0, 21.0]]))[0]) == 0
    assert len(blob_peaks(img, log, exclude=np.array([[10.0, 10.0]]))[0]) == 1


def _run(blobs: bool, seed: int = 3, n_frames: int = 14, blob_share: float = 1.0):
    """Six marks in two views; from frame 5 a dark vertical line runs 5 px right of mark 0 in view
    0, so its dot has no top-hat peak there. Returns (view 0 tracks, true uv (2, F, P, 2)). The trackers'
    own step takes no blobs: only the recovery's ``blobs`` is measured."""
    from dataclasses import replace
    cams, uv, bases, trackers, limit, rng = six_marks(seed, n_frames)
    trackers = [MarkerTracker(uv[v, 0], replace(_log(trackers[v].cfg), blobs=False)) for v in range(2)]
    cols = np.arange(160)[None, :]
    for f in range(n_frames):
        images = []
        for v in range(2):
            img = draw_dots(bases[v].copy(), uv[v, f], depth=0.2)
            if v == 0 and f >= 5:
                img = img - 0.35 * np.exp(-((cols - uv[0, f, 0, 0] - 5.0) ** 2) / (2 * 2.5 ** 2))
            images.append(frame(img, np.zeros((0, 2)), rng, noise=0.003))
        for v in range(2):
            trackers[v].step(images[v])
        if f > 0:
            recover_along_epipolar(trackers, images, cams, limit.limit(), blobs=blobs, blob_share=blob_share)
            check_views(trackers, cams, limit)
    return trackers[0].tracks(), uv


def test_a_dot_merged_into_a_dark_line_is_recovered_only_with_blobs():
    off, uv = _run(blobs=False)
    on, _ = _run(blobs=True)
    err_on = np.linalg.norm(on.uv[5:, 0] - uv[0, 5:, 0], axis=1)
    assert on.visible[5:, 0].sum() > off.visible[5:, 0].sum()
    assert on.visible[5:, 0].mean() > 0.5
    assert np.nanmax(err_on[on.visible[5:, 0]]) < 1.0
    # a blob held to half the reach and band is still taken where it is the marker's dot
    half, _ = _run(blobs=True, blob_share=0.5)
    assert half.visible[5:, 0].mean() > 0.5


def test_the_setting_must_be_a_bool():
    from lipgen.recon.settings import ReconstructSettings
    with pytest.raises(ValueError, match="epipolar_blobs must be True or False"):
        ReconstructSettings(epipolar_blobs=1)
    with pytest.raises(ValueError, match="epipolar_blob_share must be in"):
        ReconstructSettings(epipolar_blob_share=0.0)
    with pytest.raises(ValueError, match="epipolar_blob_share must be in"):
        ReconstructSettings(epipolar_blob_share=True)
    with pytest.raises(ValueError, match="confirm_blobs must be True or False, got 1"):
        ReconstructSettings(confirm_blobs=1)
    default = ReconstructSettings()
    assert default.epipolar_blobs is True and default.epipolar_blob_share == 0.5   # hard18's E2
    assert ReconstructSettings(epipolar_blobs=False).epipolar_blobs is False       # the old recovery


def _one_view(blobs: bool, n_frames: int = 14, blob_share: float = 1.0, line_px: float = 5.0, seed: int = 3):
    """One view of ``_run``'s six marks (its view 0), the same dark line ``line_px`` right of mark 0
    from frame 5, tracked by the tracker's own step alone (no other view, no recovery).
    Returns (tracks, true uv (F, P, 2))."""
    from dataclasses import replace
    cams, uv, bases, trackers, limit, rng = six_marks(seed, n_frames)
    tracker = MarkerTracker(uv[0, 0], replace(_log(trackers[0].cfg), blobs=blobs, blob_share=blob_share))
    cols = np.arange(160)[None, :]
    for f in range(n_frames):
        img = draw_dots(bases[0].copy(), uv[0, f], depth=0.2)
        if f >= 5:
            img = img - 0.35 * np.exp(-((cols - uv[0, f, 0, 0] - line_px) ** 2) / (2 * 2.5 ** 2))
        tracker.step(frame(img, np.zeros((0, 2)), rng, noise=0.003))
    return tracker.tracks(), uv[0]


def test_the_tracker_holds_a_dot_on_a_dark_lines_flank_only_with_blobs():
    off, uv = _one_view(blobs=False)
    on, _ = _one_view(blobs=True)
    # marks 0 and 3 (the column the line runs beside; grid x = -8)
    assert off.visible[5:, 0].mean() < 0.2                 # lost: the top-hat has no dot there
    assert on.visible[5:, [0, 3]].all()                     # held through every frame
    err = np.linalg.norm(on.uv[5:, [0, 3]] - uv[5:, [0, 3]], axis=-1)
    assert err.max() < 1.0
    # the marks away from the line are untouched by the candidates
    far = [1, 2, 4, 5]
    assert np.array_equal(on.visible[:, far], off.visible[:, far])
    assert np.allclose(on.uv[:, far], off.uv[:, far], equal_nan=True)


def test_blobs_off_is_the_old_step_bit_for_bit():
    a, _ = _one_view(blobs=False)
    _, uv, _, trackers, _, _ = six_marks(3, 14)
    assert trackers[0].cfg.blobs is True                    # the default since xc27
    b, _ = _one_view(blobs=False, blob_share=0.5)           # the share alone changes nothing
    assert np.array_equal(a.uv, b.uv, equal_nan=True) and np.array_equal(a.status, b.status)


def test_a_blob_darker_than_the_markers_own_dot_allows_is_not_taken():
    from lipgen.recon.blobs import blob_allowed
    guess = np.array([[10.0, 10.0], [30.0, 10.0]])
    blobs = np.array([[12.0, 10.0], [13.0, 10.0], [27.0, 10.0]])
    own = np.array([0.1, np.nan])
    need = np.array([True, True])
    ok = blob_allowed(blobs, np.array([0.08, 0.3, 0.1]), guess, guess, np.full(2, 8.0), np.full(2, 3.0),
                      need, own, (0.5, 2.0))
    # blob 0: as dark as marker 0's dot, near it; blob 1: 3x its dot; blob 2: marker 1's, whose dot is unknown
    assert ok.tolist() == [[True, False, False], [False, False, False]]
    ok = blob_allowed(blobs, np.full(3, 0.1), guess, guess, np.full(2, 8.0), np.full(2, 3.0),
                      np.array([False, True]), np.array([0.1, 0.1]), (0.5, 2.0))
    assert ok.tolist() == [[False, False, False], [False, False, True]]   # only a marker that needs one


def test_the_tracker_settings_refuse_bad_blob_values():
    with pytest.raises(ValueError, match="blobs must be True or False"):
        TrackerSettings(blobs=1)
    for bad in (0.0, 1.5, float("nan")):
        with pytest.raises(ValueError, match="blob_share must be a number in"):
            TrackerSettings(blob_share=bad)


def test_a_held_dot_is_held_on_blobs_by_the_correlation_alone():
    # blob_prediction=False: a blob is taken only where the template found it, frame after frame.
    # The line darkens over frames 5-8 (a sudden one drops the correlation under its floor).
    from dataclasses import replace
    runs = {}
    for on in (False, True):
        cams, uv, bases, trackers, limit, rng = six_marks(3, 14)
        tracker = MarkerTracker(uv[0, 0], replace(_log(trackers[0].cfg), blobs=on, blob_prediction=False))
        cols = np.arange(160)[None, :]
        for f in range(14):
            img = draw_dots(bases[0].copy(), uv[0, f], depth=0.2)
            depth = 0.35 * np.clip((f - 4) / 4, 0, 1)
            img = img - depth * np.exp(-((cols - uv[0, f, 0, 0] - 5.0) ** 2) / (2 * 2.5 ** 2))
            tracker.step(frame(img, np.zeros((0, 2)), rng, noise=0.003))
        runs[on] = tracker.tracks()
    assert runs[False].visible[8:, 0].mean() < 0.2
    assert runs[True].visible[5:, [0, 3]].all()
    err = np.linalg.norm(runs[True].uv[5:, [0, 3]] - uv[0, 5:, [0, 3]].transpose(1, 0, 2), axis=-1)
    assert err.max() < 1.0
    assert not np.isin(runs[True].status[5:, [0, 3]], [RECOVERED]).any()   # never re-acquired on a blob
    with pytest.raises(ValueError, match="blob_prediction must be True or False"):
        TrackerSettings(blob_prediction=0)


@pytest.mark.parametrize("bad", [0, 1.5, float("nan"), True, "0.5", None])
def test_blob_share_is_refused_with_its_range(bad):
    from lipgen.recon.tracks import TrackerSettings

    with pytest.raises(ValueError, match=r"blob_share must be a number in \(0, 1\]"):
        TrackerSettings(blob_share=bad)


def test_the_response_passed_in_gives_the_same_peaks():
    """dot_peaks and blob_peaks with the tracker's response passed in find what they find on their own."""
    from lipgen.recon.blobs import blob_peaks
    from lipgen.recon.dots import DotSettings, dot_peaks, dot_response

    rng = np.random.default_rng(4)
    g = 0.7 + 0.02 * rng.normal(size=(60, 80))
    rows, cols = np.mgrid[0:60, 0:80].astype(float)
    for u, v in [(20.3, 15.7), (50.1, 30.2), (33.6, 44.4)]:
        g -= 0.15 * np.exp(-((cols - u) ** 2 + (rows - v) ** 2) / (2 * 1.3 ** 2))
    s = DotSettings(sigma=1.3, blob_response="log")
    r = dot_response(g, s)
    for a, b in zip(dot_peaks(g, s), dot_peaks(g, s, None, r), strict=True):
        assert np.array_equal(a, b)
    for a, b in zip(blob_peaks(g, s), blob_peaks(g, s, None, r), strict=True):
        assert np.array_equal(a, b)
    assert len(dot_peaks(g, s)[0]) >= 3


def test_a_blob_candidate_is_fitted_to_sub_pixel():
    """blob_candidates on a dot at (24.3, 20.2) beside a dark line: within 0.3 px (a whole-pixel peak is
    0.36 px off), and a centre farther than its radius keeps nothing."""
    from lipgen.recon.blobs import blob_candidates
    from lipgen.recon.dots import dot_response

    y, x = np.mgrid[:41, :61].astype(float)
    img = 0.7 * (1 - 0.5 * np.exp(-((x - 30) ** 2) / (2 * 2.5 ** 2))) \
        * (1 - 0.25 * np.exp(-((x - 24.3) ** 2 + (y - 20.2) ** 2) / (2 * 1.5 ** 2)))
    s = DotSettings(sigma=1.5, blob_response="log")
    resp = dot_response(img, s)
    lo = np.zeros(2, dtype=int)
    uv, strength = blob_candidates(img, resp, lo, s, np.array([[25.0, 20.0]]), np.array([4.0]),
                                   np.zeros((0, 2)), img)
    assert len(uv) == 1 and np.linalg.norm(uv[0] - [24.3, 20.2]) < 0.3 and strength[0] > 0
    far, _ = blob_candidates(img, resp, lo, s, np.array([[10.0, 10.0]]), np.array([4.0]), np.zeros((0, 2)),
                             img)
    assert len(far) == 0


def test_a_blob_nearer_another_markers_guess_is_not_taken():
    """blob_allowed: a blob within marker 0's reach but nearer marker 1's guess goes to neither marker 0
    nor (without need) marker 1; by the correlation's candidate (gates) alone it is taken; too faint or
    too dark against the marker's own dot, refused."""
    from lipgen.recon.blobs import blob_allowed

    guess = np.array([[10.0, 10.0], [14.0, 10.0]])
    cand = guess.copy()
    own = np.array([0.2, 0.2])
    need = np.array([True, False])
    reach, none, ratios = np.array([3.0, 3.0]), np.zeros(2), (0.5, 2.0)
    blob = np.array([[12.5, 10.0]])                       # 2.5 px from marker 0, 1.5 px from marker 1
    ok = blob_allowed(blob, np.array([0.2]), guess, cand, reach, none, need, own, ratios)
    assert not ok.any()
    blob = np.array([[11.0, 10.0]])                       # nearer marker 0
    ok = blob_allowed(blob, np.array([0.2]), guess, cand, reach, none, need, own, ratios)
    assert ok[:, 0].tolist() == [True, False]
    far_cand = np.array([[11.2, 10.0], [14.0, 10.0]])   # the correlation by it; the guess out of reach
    short = np.array([0.5, 0.5])
    ok = blob_allowed(blob, np.array([0.2]), guess, far_cand, short, short, need, own, ratios)
    assert ok[:, 0].tolist() == [True, False]
    for s in (0.05, 0.9):   # a quarter, and 4.5 times, the marker's own darkness
        assert not blob_allowed(blob, np.array([s]), guess, cand, reach, none, need, own, ratios).any()


@pytest.mark.parametrize("gap", [3.5, 4.0])
def test_a_dot_closer_to_the_line_is_a_pit_of_curvature_but_no_laplacian_peak(gap):
    # nearer the line the Laplacian's peak merges into the line's flank; the smaller principal
    # curvature is still positive at the dot only
    img = _dot_by_a_line(gap)
    truth = [30 - gap, 20]
    log_uv, _ = blob_peaks(img, DotSettings(sigma=1.5, blob_response="log"))
    assert len(log_uv) == 0 or np.linalg.norm(log_uv - truth, axis=1).min() > 1.5
    uv, strength = blob_peaks(img, DotSettings(sigma=1.5, blob_response="hessian"))
    assert np.linalg.norm(uv - truth, axis=1).min() <= 0.5
    assert np.all(strength > 0)


def test_the_pit_response_of_a_line_and_a_slope_is_not_positive():
    from lipgen.recon.blobs import pit_response

    y, x = np.mgrid[:41, :61].astype(float)
    line = 0.7 * (1 - 0.5 * np.exp(-((x - 30) ** 2) / (2 * 2.5 ** 2)))
    small, large = pit_response(line, 1.0)
    assert small[5:-5, 5:-5].max() < 1e-6 and large[20, 30] > 0      # curved across only
    small, _ = pit_response(0.3 + 0.01 * x, 1.0)     # a slope: no curvature (to the kernels' 1e-4)
    assert np.abs(small[5:-5, 5:-5]).max() < 1e-4


def test_an_unknown_blob_response_is_refused_with_the_choices():
    with pytest.raises(ValueError, match="blob_response.*'log', 'hessian'"):
        DotSettings(blob_response="dog")


def _line_and_hidden(hide: bool, confirm: bool, n_frames: int = 14, seed: int = 3):
    """``_one_view``'s dark line beside mark 0 in view 0 from frame 5, both views tracked with blobs;
    with ``hide`` mark 0's dot is gone from view 1 from frame 5 (a fold over it). Each image:
    :func:`confirm_blobs` (with ``confirm``), then :func:`check_views`. Returns (trackers, true uv,
    what confirm_blobs withdrew (F, 2, P))."""
    from dataclasses import replace

    from lipgen.recon.viewcheck import confirm_blobs
    cams, uv, bases, trackers, limit, rng = six_marks(seed, n_frames)
    trackers = [MarkerTracker(uv[v, 0], replace(_log(trackers[v].cfg), blobs=True)) for v in range(2)]
    cols = np.arange(160)[None, :]
    withdrawn = np.zeros((n_frames, 2, 6), dtype=bool)
    for f in range(n_frames):
        for v in range(2):
            marks = uv[v, f][1:] if (hide and v == 1 and f >= 5) else uv[v, f]
            img = draw_dots(bases[v].copy(), marks, depth=0.2)
            if v == 0 and f >= 5:
                img = img - 0.35 * np.exp(-((cols - uv[0, f, 0, 0] - 5.0) ** 2) / (2 * 2.5 ** 2))
            trackers[v].step(frame(img, np.zeros((0, 2)), rng, noise=0.003))
        if f > 0:
            if confirm:
                withdrawn[f] = confirm_blobs(trackers)
            check_views(trackers, cams, limit)
    return trackers, uv, withdrawn


def test_a_blob_sighting_stands_only_where_the_other_view_sees_the_marker():
    # both views see mark 0: its blob sightings in view 0 stand and are right
    seen, uv, withdrawn = _line_and_hidden(hide=False, confirm=True)
    tracks = seen[0].tracks()
    assert not withdrawn.any()
    assert tracks.visible[5:, 0].all()
    assert np.linalg.norm(tracks.uv[5:, 0] - uv[0, 5:, 0], axis=1).max() < 1.0
    # hidden in view 1: without the guard view 0 holds it on the blob alone; with it, view 0 loses it
    alone, _, _ = _line_and_hidden(hide=True, confirm=False)
    assert alone[0].tracks().visible[5:, 0].all() and not alone[1].tracks().visible[6:, 0].any()
    guarded, _, withdrawn = _line_and_hidden(hide=True, confirm=True)
    g = guarded[0].tracks()
    assert not g.visible[6:, 0].any()
    assert withdrawn[6:, 0, 0].all() and not withdrawn[:, :, 1:].any() and not withdrawn[:, 1].any()
    assert not guarded[0]._rejected[6][0]          # withdrawn as a guess, not a rejected sighting
    # the other marks are untouched
    assert np.array_equal(g.visible[:, 1:], alone[0].tracks().visible[:, 1:])


def test_the_tracker_flags_its_blob_sightings_only():
    trackers, _, _ = _line_and_hidden(hide=False, confirm=False, n_frames=8)
    # the last image: marks 0 and 3, the column the line runs beside (grid x = -8)
    assert trackers[0].blobbed.tolist() == [True, False, False, True, False, False]
    assert not trackers[1].blobbed.any()
