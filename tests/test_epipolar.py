"""Faint dots found again on the other view's epipolar line (lipgen.recon.epipolar)."""

import numpy as np
import pytest
from synthetic_images import background, draw_dots, frame
from test_raygap import _two_views

from lipgen.recon.dots import DotSettings, detect_dots
from lipgen.recon.epipolar import recover_along_epipolar
from lipgen.recon.raygap import RayGapLimit, px_per_mm
from lipgen.recon.track import MarkerTracker, TrackerSettings
from lipgen.recon.viewcheck import check_views

FAINT = 0.07    # depth of mark 0's dot in view 0 once it pales (the others: 0.2): under the contrast floor


def six_marks(seed: int, n_frames: int):
    """Two views of six marks moving a little: (cameras, true uv (2, F, 6, 2), each view's textured
    background, the trackers started on frame 0, a ray-gap limit, the generator for the frames' noise)."""
    cams = _two_views()
    rng = np.random.default_rng(seed)
    grid = np.array([(x, y, 0.0) for y in (-6.0, 6.0) for x in (-8.0, 0.0, 8.0)])
    t = np.arange(n_frames)[:, None, None]
    marks = grid[None] + np.array([1.5, 1.0, 2.0]) * np.sin(0.3 * t)
    uv = np.stack([np.stack([c.project(m) for m in marks]) for c in cams])
    bases = [background((120, 160), rng, texture=0.03) for _ in cams]
    # No correlation-only sightings: a dot must be found as a dot or not at all.
    settings = TrackerSettings(dots=DotSettings(sigma=1.5), confident_correlation=1.0)
    trackers = [MarkerTracker(uv[v, 0], settings) for v in range(2)]
    limit = RayGapLimit(2.0, k=8.0, floor=1.0 / px_per_mm(cams), min_samples=30)
    return cams, uv, bases, trackers, limit, rng


def _run(recover: bool, lure: bool, seed: int = 3, n_frames: int = 16):
    """Track 6 marks in two views; from frame 5 mark 0's dot in view 0 is faint (under the
    detector's contrast floor), and with ``lure`` a second faint blob sits 7 px beside it on the
    epipolar line (which runs along the rows). Returns (tracks per view, true uv (2, F, P, 2))."""
    cams, uv, bases, trackers, limit, rng = six_marks(seed, n_frames)
    for f in range(n_frames):
        images = []
        for v in range(2):
            img = bases[v].copy()
            pale = (v == 0) & (f >= 5)
            img = draw_dots(img, uv[v, f][1:] if pale else uv[v, f], depth=0.2)
            if pale:
                img = draw_dots(img, uv[v, f][:1], depth=FAINT)
                if lure:
                    img = draw_dots(img, uv[v, f][:1] + [7.0, 0.0], depth=FAINT)
            images.append(frame(img, np.zeros((0, 2)), rng, noise=0.003))
        for v in range(2):
            trackers[v].step(images[v])
        if f > 0:
            if recover:
                recover_along_epipolar(trackers, images, cams, limit.limit())
            check_views(trackers, cams, limit)
    return [tr.tracks() for tr in trackers], uv, images


def test_a_faint_dot_under_the_contrast_floor_is_found_on_the_epipolar_line():
    tracks, uv, images = _run(recover=True, lure=False)
    # The detector alone does not see the pale dot.
    found, _ = detect_dots(images[0], DotSettings(sigma=1.5))
    assert np.linalg.norm(found - uv[0, -1, 0], axis=1).min() > 2
    t0 = tracks[0]
    assert t0.visible[5:, 0].mean() > 0.5
    err = np.linalg.norm(t0.uv[5:, 0] - uv[0, 5:, 0], axis=1)[t0.visible[5:, 0]]
    assert err.max() < 0.5
    off, _, _ = _run(recover=False, lure=False)
    assert not off[0].visible[6:, 0].any(), "without the recovery the pale dot is lost"


def test_a_faint_blob_on_the_line_beyond_the_reach_is_never_taken():
    tracks, uv, _ = _run(recover=True, lure=True)
    t0 = tracks[0]
    err = np.linalg.norm(t0.uv[5:, 0] - uv[0, 5:, 0], axis=1)
    assert not (t0.visible[5:, 0] & (err > 1.0)).any(), "the lure is never taken"
    assert (t0.visible[5:, 0] & (err < 0.5)).any(), "the pale dot beside it still is"


def test_bad_settings_are_refused():
    cams = _two_views()
    trackers = [MarkerTracker(np.zeros((2, 2))) for _ in range(2)]
    with pytest.raises(ValueError, match="gap_share"):
        recover_along_epipolar(trackers, [np.zeros((8, 8))] * 2, cams, 1.0, gap_share=0.0)
