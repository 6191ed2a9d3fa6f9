"""A marker whose identity later frames contradict is re-checked and re-tracked (lipgen.recon.recheck)."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_images import background, frame
from test_firstframe import _layout, _lure_on_epipolar_line
from test_raygap import _two_views

from lipgen.recon.jumps import StepLimit
from lipgen.recon.recheck import IdentityCheck
from lipgen.recon.track import MarkerTracker, TrackerSettings
from lipgen.recon.viewcheck import check_views

BAD, F = 3, 10


def _clip(lure: bool, recheck: bool, seed: int = 2, stale: float | None = None):
    """14 marks on a curved patch swaying in front of the two views. With ``lure``, view 1 also
    shows a dot 8 mm along view 0's ray through mark BAD (on the epipolar line of its view-0 dot:
    the rays meet), moving with it, and view 1's first frame is matched to it. Returns the
    (virtual, real) tracks, the true uv (2, F, P, 2) and the IdentityCheck (or None). With ``stale``,
    every marker's frames-since count is set to it before the check (as for a twin the view checks
    did not keep), and the counts after it are kept in ``check.ages``."""
    cams = _two_views()
    model = _layout()
    rng = np.random.default_rng(seed)
    t = np.arange(F)[:, None, None]
    marks = model[None] + [0.0, 0.0, 3.0] + np.array([1.0, 0.8, 1.5]) * np.sin(0.3 * t)
    uv = np.stack([np.stack([c.project(m) for m in marks]) for c in cams])        # (2, F, P, 2)
    lures = np.stack([_lure_on_epipolar_line(cams, m[BAD], 8.0) for m in marks])
    bases = [background((120, 160), rng) for _ in cams]
    trackers = []
    for v in range(2):
        init = uv[v, 0].copy()
        if lure and v == 1:
            init[BAD] = lures[0]
        trackers.append(MarkerTracker(init, TrackerSettings(acquire_gate=6.0),
                                      reference_uv=np.stack([c.project(model) for c in cams])[v]))
    check = IdentityCheck(model) if recheck else None
    steps, last3d, since = StepLimit(len(model), 4.0), np.full((len(model), 3), np.nan), np.ones(len(model))
    for f in range(F):
        images = []
        for v in range(2):
            pts = uv[v, f]
            if lure and v == 1:
                pts = np.vstack([pts, lures[f][None]])
            images.append(frame(bases[v], pts, rng))
            trackers[v].step(images[v])
        if f > 0:
            check_views(trackers, cams, 1.0, last3d, steps, since)
            if check is not None:
                if stale is not None:
                    since[:] = stale
                check.step(trackers, images, cams, 1.0, last3d, steps, since=since)
                check.ages = [*getattr(check, "ages", []), since.copy()]
    return [tr.tracks() for tr in trackers], uv, check


def test_a_contradicted_identity_is_rechecked_and_retracked_forward_and_backward():
    wrong, uv, _ = _clip(lure=True, recheck=False)
    err = np.linalg.norm(wrong[1].uv[:, BAD] - uv[1, :, BAD], axis=1)
    assert np.all(err > 5.0) and wrong[1].visible[:, BAD].all(), "without it the lure is followed"
    tracks, uv, check = _clip(lure=True, recheck=True)
    assert [(k, i, vs) for k, i, vs, _ in check.changes] == [(3, BAD, (1,))], "fired once, 3 frames in"
    tr = tracks[1]
    assert tr.visible[:, BAD].all(), "the frames before are re-tracked on the marker's own dot"
    err = np.linalg.norm(tr.uv[:, BAD] - uv[1, :, BAD], axis=1)
    assert err.max() < 0.5
    assert not tr.rejected[:, BAD].any()
    others = np.delete(np.arange(uv.shape[2]), BAD)
    for v in range(2):
        assert np.nanmax(np.linalg.norm(tracks[v].uv[:, others] - uv[v][:, others], axis=2)) < 0.5


def test_a_retracked_markers_point_is_this_frames():
    # The view checks reset the count of the markers they keep; a marker they did not keep (a twin
    # resolved after them) still has an old one. The check re-tracks BAD 3 frames in and sets its
    # last point: its count becomes 1, the others' stay as they were.
    _, _, check = _clip(lure=True, recheck=True, stale=7.0)
    assert [(k, i) for k, i, _, _ in check.changes] == [(3, BAD)]
    ages = check.ages[2]  # frame 3 (the check runs from frame 1)
    assert ages[BAD] == 1 and np.all(np.delete(ages, BAD) == 7)
    assert all(np.all(a == 7) for k, a in enumerate(check.ages) if k != 2), "only where it fires"

def test_a_right_clip_is_left_alone():
    plain, _, _ = _clip(lure=False, recheck=False)
    tracks, _, check = _clip(lure=False, recheck=True)
    assert check.changes == []
    for v in range(2):
        # Equal up to rounding: numpy's SIMD sums may group differently between two identical runs
        # (3e-10 px seen on the CI machine); a real change moves a sighting by far more.
        np.testing.assert_allclose(tracks[v].uv, plain[v].uv, rtol=0, atol=1e-7)


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match=r"rest_points must have shape \(P, 3\), got \(4, 2\)"):
        IdentityCheck(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="frames must be at least 1, got 0"):
        IdentityCheck(np.zeros((4, 3)), frames=0)
