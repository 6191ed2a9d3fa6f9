"""The first frame re-posed (:mod:`lipgen.recon.firstpose`, :func:`lipgen.recon.stereo_init.repose_layout`):
a layout far from the subject's pose is moved to where the two views' dots place it."""

import numpy as np
import pytest
from test_firstframe_floor import run_to_the_first_frame
from test_raygap import _two_views

from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.stereo_init import repose_layout


def _layout():
    """14 marks on a curved patch (two rows, 6 mm apart), mm."""
    x = np.linspace(-15.0, 15.0, 7)
    return np.array([(xi, y, 0.02 * xi ** 2) for y in (-3.0, 3.0) for xi in x])


def _pose(points, deg, shift):
    a = np.deg2rad(deg)
    R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    return points @ R.T + shift


@pytest.mark.parametrize("deg, shift", [(0.0, (25.0, -12.0, 4.0)), (12.0, (-30.0, 8.0, -6.0))])
def test_a_far_layout_is_re_posed_among_lures(deg, shift):
    """The subject 28-32 mm from the layout's pose, turned 0 or 12 degrees; each view also shows 12
    lures (no partner in the other view) and 4 marks are missing in one view. The re-posed layout
    projects within 0.05 px of the subject's dots; the layout at rest was 50+ px off."""
    cams = _two_views()
    model = _layout()
    subject = _pose(model, deg, np.array(shift))
    rng = np.random.default_rng(3)
    views = []
    for v, cam in enumerate(cams):
        uv = cam.project(subject)
        if v == 0:
            uv = uv[4:]                                   # 4 marks too faint in the mirror
        views.append(np.vstack([uv, rng.uniform([0, 0], [160, 120], (12, 2))]))
    moved = repose_layout(views[0], views[1], cams, model, reach=40.0)
    assert moved is not None
    for cam in cams:
        err = np.linalg.norm(cam.project(moved) - cam.project(subject), axis=1)
        assert err.max() < 0.05
        assert np.linalg.norm(cam.project(model) - cam.project(subject), axis=1).min() > 50


def test_nothing_is_placed_from_too_few_pairs():
    cams = _two_views()
    model = _layout()
    uv = [cam.project(model[:5]) for cam in cams]          # 5 marks in both views: under least = 6
    assert repose_layout(uv[0], uv[1], cams, model) is None
    assert repose_layout(uv[0], uv[1], cams, model, least=5) is not None
    # Farther than the reach plus the layout's span (30 mm), no offset puts any marker on a point
    far = [cam.project(model + [75.0, 0, 0]) for cam in cams]
    assert repose_layout(far[0], far[1], cams, model, reach=40.0) is None


@pytest.mark.parametrize("bad", [0, -1, 2.5, True, "6"])
def test_the_setting_is_checked(bad):
    with pytest.raises(ValueError, match="first_frame_repose"):
        ReconstructSettings(first_frame_repose=bad)


def test_a_tracker_started_on_dots_under_its_floor_steps_through_frame_0():
    """Frame 0 matched at a lowered floor (first_frame_floor, first_frame_repose) leaves the tracker's own
    fixed-floor detection empty there: the step keeps the markers and does not fail (it did: argmin of
    an empty sequence)."""
    from dataclasses import replace

    from lipgen.recon.dots import DotSettings, detect_dots
    from lipgen.recon.track import LOST, MarkerTracker
    from lipgen.recon.tracks import TrackerSettings

    rows, cols = np.mgrid[0:100, 0:100].astype(float)
    img = np.full((100, 100), 0.8)
    for u, v in [(30.3, 40.6), (50.3, 40.6), (70.3, 40.6)]:
        img -= 0.09 * np.exp(-((cols - u) ** 2 + (rows - v) ** 2) / (2 * 1.3 ** 2))
    s = TrackerSettings(dots=DotSettings(sigma=1.3))
    assert len(detect_dots(img, s.dots)[0]) == 0
    low = detect_dots(img, replace(s.dots, min_contrast=0.05))[0]
    assert len(low) == 3
    uv, status, _ = MarkerTracker(low, s).step(img)
    assert np.all(status != LOST) and np.allclose(uv, low, atol=0.5)


class _Calls:
    """Stand-ins for first_frame's steps: the first pass pairs ``first`` markers, the retry ``retry``."""

    def __init__(self, monkeypatch, first, retry, P=8):
        import lipgen.recon.firstpose as firstpose

        self.reposed, self.P = 0, P
        det = [(np.zeros((3, 2)), np.ones(3)), (np.zeros((3, 2)), np.ones(3))]
        monkeypatch.setattr(firstpose, "first_frame_dots", lambda *a: det)
        monkeypatch.setattr(firstpose, "detect_dots", lambda img, dots: (np.ones((5, 2)), np.ones(5)))

        def match(detected, exp, *a):
            n = first if exp is self.exp else retry
            inits = [np.full((P, 2), np.nan), np.full((P, 2), np.nan)]
            inits[0][:n] = inits[1][:n] = 1.0
            return inits, np.zeros(P, dtype=bool)

        def repose(*a):
            self.reposed += 1
            return np.zeros((P, 3))

        monkeypatch.setattr(firstpose, "match_first_frame_views", match)
        monkeypatch.setattr(firstpose, "repose_layout", repose)
        self.exp = np.zeros((2, P, 2))

    def run(self, repose):
        from lipgen.recon.firstpose import first_frame

        class Cam:
            def project(self, X):
                return np.zeros((len(X), 2))

        settings = ReconstructSettings(first_frame_repose=repose)
        return first_frame([None, None], self.exp, settings, (Cam(), Cam()), np.zeros((self.P, 3)))


@pytest.mark.parametrize("repose, first, retry, tried, kept", [
    (None, 2, 7, False, 2),   # off: the first pass, no retry
    (6, 6, 8, False, 6),      # enough markers paired: no retry
    (6, 2, 7, True, 7),       # too few, the retry pairs more: taken
    (6, 2, 2, True, 2),       # the retry pairs no more: the first pass kept
])
def test_the_retry_is_tried_and_kept_only_where_it_should_be(monkeypatch, repose, first, retry, tried, kept):
    calls = _Calls(monkeypatch, first, retry)
    inits, bad, found = calls.run(repose)
    assert calls.reposed == (1 if tried else 0)
    assert int(np.all(np.isfinite(inits[0]), axis=1).sum()) == kept
    taken = tried and retry > first
    assert max(len(f) for f in found) == (5 if taken else 3)   # one view's dots at the least floor


def test_the_repose_setting_reaches_the_first_frame(monkeypatch):
    """track_raw_frames hands first_frame_repose to lipgen.recon.firstpose.first_frame."""
    import lipgen.recon.steps as steps
    seen = {}

    def spy(views, exp, settings, *a, **k):
        seen["repose"] = settings.first_frame_repose
        raise RuntimeError("stop")

    monkeypatch.setattr(steps, "first_frame", spy)
    run_to_the_first_frame(ReconstructSettings(first_frame_repose=5))
    assert seen == {"repose": 5}


def test_the_lure_filter_keeps_every_dot_when_no_pair_is_near_the_layout():
    """layout_dots with every pair of dots beyond the reach of the layout: nothing is known, every dot kept
    (it failed: the minimum over no close point)."""
    from lipgen.recon.stereo_init import layout_dots

    cams = _two_views()
    model = _layout()
    far = [cam.project(model + [75.0, 0, 0]) for cam in cams]
    keep_v, keep_r = layout_dots(far[0], far[1], cams, model)
    assert keep_v.all() and keep_r.all() and len(keep_v) == len(model)
