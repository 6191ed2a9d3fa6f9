"""Identity checks on the 3-D layout over time (lipgen.recon.motioncheck).

A 14-mark patch (two rows 6 mm apart, marks 5 mm apart in a row) sways in front of two views;
the trackers follow it on synthetic frames. Wrong identities that agree in both views (the ray
gap passes them) are made as the tracker would make them, and the check must drop or correct
them, while a fast right motion (the lower row dropping, a jaw opening) is left alone.
"""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_images import background, frame
from test_firstframe import _lure_on_epipolar_line
from test_raygap import _two_views

from lipgen.recon.motioncheck import MotionCheck
from lipgen.recon.track import MarkerTracker, TrackerSettings

BAD, ABOVE, F = 3, 10, 10      # mark 3: lower row, x = 0; mark 10: the upper row's mark above it


def _layout():
    """The 14 marks facing the cameras (the cameras look along +z: the face's front is -z here)."""
    x = np.linspace(-15.0, 15.0, 7)
    return np.array([(xi, y, -0.02 * xi ** 2) for y in (-3.0, 3.0) for xi in x])


def _marks(jaw: float = 0.0, back: float = 0.0) -> np.ndarray:
    """(F, 14, 3) the patch swaying; with ``jaw``, the lower row drops ``jaw`` mm a frame from frame 3,
    and with ``back`` it also moves ``back`` mm a frame away from the cameras (the jaw's rotation)."""
    t = np.arange(F)[:, None, None]
    marks = _layout()[None] + [0.0, 0.0, 3.0] + np.array([1.0, 0.8, 1.5]) * np.sin(0.3 * t)
    ramp = np.clip(np.arange(F) - 2, 0, None)[:, None]
    marks[:, :7, 1] -= jaw * ramp
    marks[:, :7, 2] += back * ramp
    return marks


def _smooth_covariance(width: float = 6.0) -> np.ndarray:
    """(42, 42) a smooth prior on the 14 marks' displacements (near marks move alike), node-major, for
    the check's physics-prior route (:func:`lipgen.recon.layoutprior.predict_layout_physics`)."""
    d = np.linalg.norm(_layout()[:, None] - _layout()[None], axis=2)
    return np.kron(np.exp(-0.5 * (d / width) ** 2), np.eye(3))


def _run(marks, inject=None, lure=None, check=True, seed=1, prior="rest"):
    """Track the marks in both views; ``inject(f, trackers, uv)`` may change a frame's sightings
    before the check; ``lure`` (F, 2) draws an extra dot in view 1 and starts mark BAD there;
    ``prior``: the check's layout prediction, "rest" or "physics" (:func:`_smooth_covariance`).
    Returns the (virtual, real) tracks, the true uv (2, F, P, 2) and the check (or None)."""
    cams = _two_views()
    uv = np.stack([np.stack([c.project(m) for m in marks]) for c in cams])
    rng = np.random.default_rng(seed)
    bases = [background((120, 160), rng) for _ in cams]
    ref = np.stack([c.project(_layout()) for c in cams])
    trackers = []
    for v in range(2):
        init = uv[v, 0].copy()
        if lure is not None and v == 1:
            init[BAD] = lure[0]
        trackers.append(MarkerTracker(init, TrackerSettings(acquire_gate=6.0), reference_uv=ref[v]))
    cov = _smooth_covariance() if prior == "physics" else None   # else the rest layout
    mc = MotionCheck(_layout(), covariance=cov) if check else None
    for f in range(len(marks)):
        images = []
        for v in range(2):
            pts = uv[v, f] if lure is None or v == 0 else np.vstack([uv[v, f], lure[f][None]])
            images.append(frame(bases[v], pts, rng))
            trackers[v].step(images[v])
        if inject is not None:
            inject(f, trackers, uv)
        if mc is not None:
            mc.step(trackers, images, cams)
    return [tr.tracks() for tr in trackers], uv, mc


def _err(tracks, uv, v, i):
    return np.linalg.norm(tracks[v].uv[:, i] - uv[v, :, i], axis=1)


@pytest.mark.parametrize("prior", ["rest", "physics"])
def test_a_row_shifted_identity_in_both_views_is_dropped_and_the_marker_found_again(prior):
    # At frame 6 the tracker puts mark BAD on the dot of the mark above it, one row (6 mm) up,
    # in both views: a pair whose rays meet, on a neighbour's point. Its step is one row; its
    # neighbours' are a fraction of a mm.
    def shift(f, trackers, uv):
        if f == 6:
            for v in range(2):
                trackers[v]._out[-1][0][BAD] = uv[v, f, ABOVE]

    plain, uv, _ = _run(_marks(), check=False)
    tracks, uv, mc = _run(_marks(), inject=shift, prior=prior)
    assert [(k, i, kind, vs) for k, i, kind, vs, _ in mc.changes] == [(6, BAD, "jump", (0, 1))]
    for v in range(2):
        assert not tracks[v].visible[6, BAD] and tracks[v].rejected[6, BAD]
        e = _err(tracks, uv, v, BAD)
        assert np.all(e[:6] < 0.5) and np.all(e[7:] < 0.5), "tracked on its own dot before and after"
        others = np.delete(np.arange(uv.shape[2]), BAD)
        np.testing.assert_allclose(tracks[v].uv[:, others], plain[v].uv[:, others], rtol=0, atol=1e-7)


@pytest.mark.parametrize("prior", ["rest", "physics"])
def test_two_markers_swapped_in_both_views_are_swapped_back(prior):
    def swap(f, trackers, uv):
        if f == 6:
            for v in range(2):
                out = trackers[v]._out[-1][0]
                out[[BAD, ABOVE]] = out[[ABOVE, BAD]]

    tracks, uv, mc = _run(_marks(), inject=swap, prior=prior)
    assert sorted((k, i, kind) for k, i, kind, _, _ in mc.changes) == [(6, BAD, "swap"), (6, ABOVE, "swap")]
    for v in range(2):
        for i in (BAD, ABOVE):
            assert tracks[v].visible[:, i].all()
            assert _err(tracks, uv, v, i).max() < 0.5


@pytest.mark.parametrize("prior", ["rest", "physics"])
def test_a_lure_behind_the_lips_on_the_epipolar_line_is_dropped_in_its_view_only(prior):
    # View 1 starts mark BAD on a dark blob 6 mm behind the mark along view 0's ray: on the
    # epipolar line of view 0's right dot, so the rays meet (at the blob). It is taken back in
    # view 1 from the first frame on; view 0 keeps the mark; view 1 acquires it on its own dot.
    marks = _marks()
    cams = _two_views()
    lure = np.stack([_lure_on_epipolar_line(cams, m[BAD], 6.0) for m in marks])
    own = np.stack([cams[1].project(m[[BAD]])[0] for m in marks])
    assert np.all(np.linalg.norm(lure - own, axis=1) > 3.0)
    tracks, uv, mc = _run(marks, lure=lure, prior=prior)
    assert (1, BAD, "run", (1,)) in [(k, i, kind, vs) for k, i, kind, vs, _ in mc.changes]
    on_lure = np.linalg.norm(tracks[1].uv[:, BAD] - lure, axis=1) < 1.0
    assert not (on_lure & tracks[0].visible[:, BAD] & tracks[1].visible[:, BAD])[1:].any(), \
        "never seen in both views on the lure after the first frame"
    assert tracks[1].rejected[0, BAD], "the first frame's sighting on the lure is taken back"
    assert tracks[0].visible[:, BAD].all() and _err(tracks, uv, 0, BAD).max() < 0.5
    e1 = _err(tracks, uv, 1, BAD)
    assert tracks[1].visible[-4:, BAD].all() and e1[-4:].max() < 0.5, "found again on its own dot"


@pytest.mark.parametrize("prior", ["rest", "physics"])
def test_a_fast_jaw_opening_is_left_alone(prior):
    # The lower row drops 2.5 mm a frame (6-7 px) while the upper row sways: a fast right motion.
    marks = _marks(jaw=2.5)
    plain, uv, _ = _run(marks, check=False)
    tracks, uv, mc = _run(marks, prior=prior)
    for v in range(2):
        assert plain[v].visible.all() and np.nanmax(np.linalg.norm(plain[v].uv - uv[v], axis=2)) < 0.5
    assert mc.changes == []
    for v in range(2):
        np.testing.assert_allclose(tracks[v].uv, plain[v].uv, rtol=0, atol=1e-7)


def test_a_jaw_opening_down_and_back_is_left_alone_with_the_physics_prior():
    # The lower row drops 2.5 mm and moves 2 mm back a frame (14 mm back at the end): the layout at
    # rest, fitted without the lower row once it is far off, predicts a closed mouth and takes the
    # row back as behind it; the prior, in which near marks move alike, follows the row.
    marks = _marks(jaw=2.5, back=2.0)
    plain, uv, _ = _run(marks, check=False)
    for v in range(2):
        assert plain[v].visible.all() and np.nanmax(np.linalg.norm(plain[v].uv - uv[v], axis=2)) < 0.5
    _, _, strict = _run(marks)
    assert {kind for _, _, kind, _, _ in strict.changes} == {"behind"}, "the layout alone drops the lower row"
    tracks, uv, mc = _run(marks, prior="physics")
    assert mc.changes == []
    for v in range(2):
        np.testing.assert_allclose(tracks[v].uv, plain[v].uv, rtol=0, atol=1e-7)


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match=r"rest_points must have shape \(P, 3\) with P >= 2, got \(4, 2\)"):
        MotionCheck(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="MotionCheck.depth must be a positive number, got 0"):
        MotionCheck(_layout(), depth=0)
    with pytest.raises(ValueError, match=r"jump_floor \(0.9\) exceeds jump_cap \(0.8\)"):
        MotionCheck(_layout(), jump_floor=0.9)
    with pytest.raises(ValueError, match=r"covariance must have shape \(42, 42\)"):
        MotionCheck(_layout(), covariance=np.eye(39))
