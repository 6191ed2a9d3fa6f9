"""Normalisation (thesis §3) against closed forms on synthetic points with known rotations."""

import numpy as np
import pytest

from lipgen.recon.normalize import fit_plane, lip_frame, lip_subsets, normalize_markers, umeyama


def _rot(axis, angle):
    c, s = np.cos(angle), np.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def _lips():
    """Upper and lower lip arcs, each exactly in a plane that contains the x direction, so the
    rest shape's lip frame is the identity. Returns markers (P, 3), upper, lower, nose."""
    x = np.linspace(-20, 20, 7)
    upper = np.column_stack([x, 6 - 0.004 * x ** 2, 8 - 0.015 * x ** 2])
    lower = np.column_stack([x[1:-1], -6 + 0.004 * x[1:-1] ** 2, 8 - 0.02 * x[1:-1] ** 2])
    corners = np.array([[-24.0, 0.0, 0.0], [24.0, 0.0, 0.0]])
    M = np.vstack([upper, lower, corners])
    return M, np.arange(7), np.arange(7, 12), np.array([0.0, 33.0, 15.0])


def test_umeyama_recovers_a_known_similarity_exactly():
    rng = np.random.default_rng(0)
    src = rng.normal(size=(10, 3))
    R = _rot(0, 0.3) @ _rot(1, -1.1) @ _rot(2, 2.0)
    dst = 2.5 * src @ R.T + [1.0, -2.0, 3.0]
    sim = umeyama(src, dst)
    assert sim.scale == pytest.approx(2.5, rel=1e-12)
    assert np.allclose(sim.rotation, R, atol=1e-12) and np.allclose(sim.translation, [1, -2, 3], atol=1e-12)
    assert np.allclose(sim.inverse().apply(dst), src, atol=1e-12)
    assert umeyama(src, dst, with_scale=False).scale == 1.0


def test_umeyama_never_returns_a_reflection():
    rng = np.random.default_rng(1)
    src = rng.normal(size=(8, 3))
    mirrored = src * [-1.0, 1.0, 1.0]
    sim = umeyama(src, mirrored)
    assert np.linalg.det(sim.rotation) == pytest.approx(1.0, abs=1e-12)
    with pytest.raises(ValueError, match="at least 3 point pairs"):
        umeyama(src[:2], src[:2])


def test_fit_plane_closed_form():
    rng = np.random.default_rng(2)
    n = np.array([1.0, 2.0, 2.0]) / 3.0
    basis = np.linalg.svd(np.eye(3) - np.outer(n, n))[0][:, :2]
    pts = rng.normal(size=(9, 2)) @ basis.T + 4.0 * n
    c, normal, flat = fit_plane(pts)
    assert abs(abs(normal @ n) - 1.0) < 1e-12 and flat < 1e-12
    with pytest.raises(ValueError, match="collinear"):
        fit_plane(np.outer(np.arange(4.0), [1.0, 1.0, 0.0]))


def test_lip_frame_removes_yaw_and_roll_exactly():
    M, up_i, lo_i, _ = _lips()
    R0, angle = lip_frame(M[up_i], M[lo_i])
    assert np.allclose(R0, np.eye(3), atol=1e-12) and angle > 0.1
    for yaw, roll in [(0.3, 0.0), (0.0, -0.25), (-0.4, 0.2)]:
        Q = _rot(1, yaw) @ _rot(2, roll)
        R, _ = lip_frame(M[up_i] @ Q.T, M[lo_i] @ Q.T)
        assert np.allclose(R, Q.T, atol=1e-12), "the lip frame turns with the head"


def test_lip_frame_passes_a_nod_through():
    # x is the plane intersection (unchanged by a rotation about x) and y comes from the global
    # up, so a nod is not normalised away: R stays the identity.
    M, up_i, lo_i, _ = _lips()
    Q = _rot(0, 0.2)
    R, _ = lip_frame(M[up_i] @ Q.T, M[lo_i] @ Q.T)
    assert np.allclose(R, np.eye(3), atol=1e-12)


def _head_frames(M, nose, poses, scale, shift):
    """Data frames: the model-frame points moved by head poses (rotation about the nose plus a
    translation), then a global similarity into some reconstruction frame."""
    X, N = [], []
    for Q, T in poses:
        world = (M - nose) @ Q.T + nose + T
        X.append(scale * world + shift)
        N.append(scale * (nose + T) + shift)
    return np.array(X), np.array(N)


def test_normalize_markers_recovers_the_model_frame_under_head_motion():
    M, up_i, lo_i, nose = _lips()
    rng = np.random.default_rng(3)
    poses = [(np.eye(3), np.zeros(3))] + [
        (_rot(1, rng.uniform(-0.4, 0.4)) @ _rot(2, rng.uniform(-0.3, 0.3)), rng.normal(0, 5, 3))
        for _ in range(5)]
    X, N = _head_frames(M, nose, poses, scale=0.8, shift=np.array([10.0, -40.0, 600.0]))
    res = normalize_markers(X, N, up_i, lo_i, M, model_nose=nose)
    assert np.allclose(res.markers, M[None], atol=1e-9)
    assert res.similarity.scale == pytest.approx(1 / 0.8, rel=1e-12) and res.fit_rms < 1e-9
    assert not res.borrowed.any()


def test_normalize_markers_keeps_a_nod_in_closed_form():
    M, up_i, lo_i, nose = _lips()
    Q = _rot(0, 0.15)
    X, N = _head_frames(M, nose, [(np.eye(3), np.zeros(3)), (Q, np.array([1.0, 2.0, 3.0]))],
                        scale=1.0, shift=np.zeros(3))
    res = normalize_markers(X, N, up_i, lo_i, M, model_nose=nose)
    assert np.allclose(res.markers[1], (M - nose) @ Q.T + nose, atol=1e-9)


def test_normalize_markers_with_lost_markers_and_borrowed_frames():
    M, up_i, lo_i, nose = _lips()
    poses = [(_rot(1, 0.1 * k), np.array([k, 0.0, 0.0])) for k in range(4)]
    X, N = _head_frames(M, nose, poses, scale=1.0, shift=np.zeros(3))
    X[1, 3] = np.nan                    # one marker lost: that frame still normalises
    X[2, lo_i[:3]] = np.nan             # too few lower-lip markers: the frame borrows a lip frame
    res = normalize_markers(X, N, up_i, lo_i, M, model_nose=nose)
    assert np.isnan(res.markers[1, 3]).all() and np.isnan(res.markers[2, lo_i[:3]]).all()
    assert np.allclose(res.markers[1, np.arange(len(M)) != 3], np.delete(M, 3, axis=0), atol=1e-9)
    assert res.borrowed.tolist() == [False, False, True, False]
    # The borrowed frame uses a neighbour's rotation (0.1 rad different): its error is bounded by it.
    err = np.nanmax(np.linalg.norm(res.markers[2] - M, axis=1))
    assert 0 < err < 0.1 * np.linalg.norm(M - nose, axis=1).max() + 1e-9


def test_normalize_markers_bad_inputs():
    M, up_i, lo_i, nose = _lips()
    X = np.repeat(M[None], 2, axis=0)
    N = np.repeat(nose[None], 2, axis=0)
    with pytest.raises(ValueError, match=r"nose must have shape \(2, 3\)"):
        normalize_markers(X, N[:1], up_i, lo_i, M)
    with pytest.raises(ValueError, match="out of range"):
        normalize_markers(X, N, [0, 1, 99], lo_i, M)
    Xn = X.copy()
    Xn[:, up_i] = np.nan
    with pytest.raises(ValueError, match="no frame has 3 visible"):
        normalize_markers(Xn, N, up_i, lo_i, M)


def test_lip_subsets_by_name():
    names = ("upper_mid", "lower_mid", "corner_left", "corner_right", "upper_left", "upper_right",
             "lower_left", "lower_right", "bow_peak_left", "bow_peak_right", "bow_dip", "lower_border_mid")
    up, lo = lip_subsets(names)
    assert up.tolist() == [0, 4, 5, 8, 9, 10] and lo.tolist() == [1, 6, 7, 11]
    with pytest.raises(ValueError, match="pass the index lists"):
        lip_subsets(["a", "b", "c"])
