"""The least-deformation head pose (lipgen.recon.headpose, normalize_markers(method=...)) against closed
forms: exact recovery of rigid motion, the first-order bias of an expression computed
independently from a dense inverse of K, equivariance under head rotation, missing markers."""

import numpy as np
import pytest

from lipgen.fem import Physics
from lipgen.mesh.procedural import lip_mesh
from lipgen.recon.headpose import MarkerMetric, least_cost_rotations, rotation_matrix, rotation_vector
from lipgen.recon.normalize import lip_subsets, normalize_markers
from lipgen.subject.motion import ACTIONS, default_subject

POSE_METHODS = ("least-force", "least-strain", "procrustes")


@pytest.fixture(scope="module")
def model():
    mesh = lip_mesh(0)
    return mesh, Physics(mesh)


def _head(rng, max_deg):
    return rotation_matrix(rng.uniform(-1, 1, 3) * np.deg2rad(max_deg) / np.sqrt(3))


def _world(M, nose, U, Qs, ts, scale=1.0, lab=None):
    """World (here: some lab frame) marks of model-frame markers M + U under head poses (Q, t)
    about an arbitrary pivot, then one similarity (scale, lab rotation)."""
    pivot = np.array([0.0, -70.0, -90.0])
    V = np.broadcast_to(M + U, (len(Qs), *M.shape))
    X = np.einsum("fij,fpj->fpi", Qs, V - pivot) + pivot + ts[:, None]
    N = np.einsum("fij,j->fi", Qs, nose - pivot) + pivot + ts
    lab = np.eye(3) if lab is None else lab
    return scale * X @ lab.T, scale * N @ lab.T


def test_rotation_vector_and_matrix_are_inverse():
    rng = np.random.default_rng(0)
    axis = rng.normal(size=(20, 3))
    w = axis / np.linalg.norm(axis, axis=1, keepdims=True) * np.geomspace(1e-10, 3.0, 20)[:, None]
    R = rotation_matrix(w)
    assert np.allclose(R @ np.swapaxes(R, 1, 2), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1.0)
    assert np.allclose(rotation_vector(R), w, atol=1e-9)
    # closed form: 90 degrees about z
    assert np.allclose(rotation_matrix([0, 0, np.pi / 2]), [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)


@pytest.mark.parametrize("method", POSE_METHODS)
def test_pure_head_motion_is_removed_exactly(model, method):
    mesh, physics = model
    M, nose = mesh.vertices[mesh.markers], mesh.nose
    rng = np.random.default_rng(1)
    F = 6
    Qs = np.stack([np.eye(3)] + [_head(rng, 10.0) for _ in range(F - 1)])
    ts = np.vstack([np.zeros(3), rng.normal(0, 5, (F - 1, 3))])
    lab = rotation_matrix([0.3, -1.0, 0.5])
    X, N = _world(M, nose, np.zeros_like(M), Qs, ts, scale=0.8, lab=lab)
    up, lo = lip_subsets(mesh.marker_names)
    res = normalize_markers(X, N, up, lo, M, model_nose=nose, reference_frame="auto", method=method,
                            physics=physics)
    assert np.allclose(res.markers, M[None], atol=1e-8)
    assert res.similarity.scale == pytest.approx(1 / 0.8, rel=1e-10)
    # the data -> model rotation of every frame is the inverse of (lab rotation o head rotation)
    R = np.einsum("ij,fjk->fik", res.similarity.rotation, res.rotations)
    assert np.allclose(np.einsum("fij,jk,fkl->fil", R, lab, Qs), np.eye(3), atol=1e-9)
    assert res.method == method and not res.borrowed.any() and np.all(res.cost < 1e-12)


def _dense_gram(physics, kind):
    """SᵀS or C_oo at the marker DOFs from a dense inverse of the free block of K (independent of
    Physics.solve and MarkerMetric)."""
    K = physics.K.toarray()
    free = physics.free_dofs
    Kinv = np.zeros_like(K)
    Kinv[np.ix_(free, free)] = np.linalg.inv(K[np.ix_(free, free)])
    d = (3 * np.asarray(physics.mesh.markers)[:, None] + np.arange(3)).ravel()
    S = Kinv[:, d]
    return S.T @ S if kind == "force" else S[d]


ONE_SIDED = [a for a in ACTIONS if a.endswith(("_left", "_right"))]


@pytest.mark.parametrize("kind", ["force", "energy"])
def test_one_sided_expressions_bias_the_pose_by_the_first_order_prediction(model, kind):
    """With a one-sided expression d and a head rotation Q, the pose error is the rotation that best
    explains d in the metric, -(JᵀWJ)⁻¹JᵀW d to first order (J: rotation about the nose of the
    rest markers), whatever Q is. Its size is what the method can confuse with head motion; the
    bound 4 deg holds for every one-sided action at full strength (the largest, a corner puller
    under the force metric, reads as 3.6 deg, see lipgen.recon.normalize)."""
    mesh, physics = model
    M, nose = mesh.vertices[mesh.markers], mesh.nose
    subject = default_subject(0)
    idx = [ACTIONS.index(a) for a in ONE_SIDED]
    U = subject.displacements(np.eye(len(ACTIONS))[idx])[:, subject.mesh.markers]
    W = np.linalg.inv(_dense_gram(physics, kind))
    A = M - nose
    J = np.zeros((len(A), 3, 3))  # d(w x a)/dw = -[a]x
    J[:, 0, 1], J[:, 0, 2], J[:, 1, 2] = A[:, 2], -A[:, 1], A[:, 0]
    J = (J - np.swapaxes(J, 1, 2)).reshape(-1, 3)
    predicted = -np.linalg.solve(J.T @ W @ J, J.T @ W @ U.reshape(len(U), -1).T).T  # (a, 3) rad
    rng = np.random.default_rng(2)
    errors = []
    for Q in (np.eye(3), _head(rng, 4.0), _head(rng, 4.0)):
        Qs = np.repeat(Q[None], len(U), axis=0)
        X, N = _world(M, nose, U, Qs, np.zeros((len(U), 3)))
        metric = MarkerMetric.from_physics(physics, kind)
        R, _, conv = least_cost_rotations(X - N[:, None], A, metric, np.ones(U.shape[:2], bool), np.eye(3))
        assert conv.all()
        errors.append(rotation_vector(np.einsum("fij,jk->fik", R, Q)))
    err = errors[0]
    for other in errors[1:]:
        assert np.allclose(other, err, atol=1e-7), "the bias must not depend on the head's rotation"
    size, pred = np.linalg.norm(err, axis=1), np.linalg.norm(predicted, axis=1)
    assert np.all(np.linalg.norm(err - predicted, axis=1) < 0.15 * pred + np.deg2rad(0.05))
    assert np.all(np.degrees(size) < (4.5 if kind == "energy" else 4.0))
    # and it is a real bias, not zero: the one-sided corner pullers read as a roll
    assert np.degrees(size).max() > 1.0


def test_missing_markers_and_borrowed_frames(model):
    mesh, physics = model
    M, nose = mesh.vertices[mesh.markers], mesh.nose
    rng = np.random.default_rng(3)
    F = 5
    Qs = np.stack([_head(rng, 5.0) for _ in range(F)])
    X, N = _world(M, nose, np.zeros_like(M), Qs, rng.normal(0, 3, (F, 3)))
    X[1, [0, 2, 5]] = np.nan  # some markers lost: the frame still normalises exactly
    X[3, 2:] = np.nan  # two left: the frame borrows its neighbour's rotation
    visible = np.all(np.isfinite(X), axis=2)
    visible[4, 7] = False  # seen but flagged invisible: treated as lost
    up, lo = lip_subsets(mesh.marker_names)
    res = normalize_markers(X, N, up, lo, M, model_nose=nose, visible=visible, method="least-force",
                            physics=physics, reference_frame=0)
    assert res.borrowed.tolist() == [False, False, False, True, False]
    assert np.isnan(res.markers[~visible]).all() and np.isfinite(res.markers[visible]).all()
    ok = visible.copy()
    ok[3] = False
    assert np.allclose(res.markers[ok], np.broadcast_to(M, X.shape)[ok], atol=1e-8)
    # the borrowed frame carries the neighbour's rotation error: the head turned between them
    # (nearest good frame: 2, the earlier of the two neighbours): frame 3 is turned by Q2ᵀ Q3 about
    # the nose, at most a chord of that angle at each marker's distance from the nose
    turn = Qs[2].T @ Qs[3]
    assert np.allclose(res.markers[3, :2], (M[:2] - nose) @ turn.T + nose, atol=1e-9)
    err = np.linalg.norm(res.markers[3, :2] - M[:2], axis=1)
    chord = 2 * np.sin(np.linalg.norm(rotation_vector(turn)) / 2) * np.linalg.norm(M[:2] - nose, axis=1)
    assert np.all((err > 0.1) & (err <= chord + 1e-9))


def test_bad_inputs(model):
    mesh, physics = model
    M, nose = mesh.vertices[mesh.markers], mesh.nose
    X, N = np.repeat(M[None], 2, axis=0), np.repeat(nose[None], 2, axis=0)
    up, lo = lip_subsets(mesh.marker_names)
    with pytest.raises(ValueError, match="unknown normalisation method 'bogus'"):
        normalize_markers(X, N, up, lo, M, model_nose=nose, method="bogus")
    with pytest.raises(ValueError, match="needs model_nose"):
        normalize_markers(X, N, up, lo, M, method="least-force", physics=physics)
    with pytest.raises(ValueError, match="pass physics="):
        normalize_markers(X, N, up, lo, M, model_nose=nose, method="least-force")
    with pytest.raises(ValueError, match="not model_markers"):
        normalize_markers(X, N, up, lo, M + 1.0, model_nose=nose, method="least-strain", physics=physics)
    Xn = X.copy()
    Xn[:, 2:] = np.nan
    with pytest.raises(ValueError, match="only 2 visible markers"):
        normalize_markers(Xn, N, up, lo, M, model_nose=nose, method="procrustes")
    with pytest.raises(ValueError, match="unknown marker metric"):
        MarkerMetric.from_physics(physics, "elastic")
    with pytest.raises(ValueError, match="metric is for 16 markers but the data have 3"):
        least_cost_rotations(M[None, :3], M[:3], MarkerMetric.euclidean(16), np.ones((1, 3), bool), np.eye(3))


def test_a_mis_measured_marker_is_left_out_of_the_pose_fit(model):
    """A marker 8 mm off in one frame (a mis-track) would turn that frame's pose; it is found
    (the pose without it costs far less), left out of the fit, and the frame's other markers come
    out exact. Full-strength one-sided expressions are never taken for outliers."""
    mesh, physics = model
    M, nose = mesh.vertices[mesh.markers], mesh.nose
    rng = np.random.default_rng(4)
    F = 4
    Qs = np.stack([_head(rng, 4.0) for _ in range(F)])
    X, N = _world(M, nose, np.zeros_like(M), Qs, rng.normal(0, 3, (F, 3)))
    X[2, 5] += [6.0, -4.0, 3.5]
    up, lo = lip_subsets(mesh.marker_names)
    kw = dict(model_nose=nose, method="least-force", physics=physics, reference_frame=0)
    plain = normalize_markers(X, N, up, lo, M, outlier_ratio=0, **kw)
    assert np.abs(plain.markers[2, :5] - M[:5]).max() > 0.1 and not plain.outliers.any()
    res = normalize_markers(X, N, up, lo, M, **kw)
    assert np.argwhere(res.outliers).tolist() == [[2, 5]]
    others = np.arange(len(M)) != 5
    assert np.allclose(res.markers[:, others], np.broadcast_to(M, X.shape)[:, others], atol=1e-8)
    assert np.linalg.norm(res.markers[2, 5] - M[5]) == pytest.approx(np.linalg.norm([6.0, -4.0, 3.5]))
    # legitimate expressions with head motion: nothing left out
    subject = default_subject(0)
    U = subject.displacements(np.eye(len(ACTIONS)))[:, subject.mesh.markers]
    Qs = np.stack([_head(rng, 4.0) for _ in range(len(U))])
    X, N = _world(M, nose, U, Qs, rng.normal(0, 3, (len(U), 3)))
    assert not normalize_markers(X, N, up, lo, M, **kw).outliers.any()
    with pytest.raises(ValueError, match="outlier_ratio must be in"):
        normalize_markers(X, N, up, lo, M, outlier_ratio=1.5, **kw)
