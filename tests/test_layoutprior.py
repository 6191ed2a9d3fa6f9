"""The layout predicted with the physics prior (:mod:`lipgen.recon.layoutprior`): exact for a moved
layout, and equal to the least-norm-force reach (an independent route) where the points are a
similarity of a deformed layout."""

import numpy as np
import pytest

from lipgen.fem import Physics
from lipgen.fem import dofs as node_dofs
from lipgen.recon.layoutprior import physics_layout_covariance, predict_layout_physics
from lipgen.recon.modelmesh import model_mesh
from lipgen.recon.stereo_init import _similarity_3d


@pytest.fixture(scope="module")
def lips():
    mesh = model_mesh("lip_mesh(0)")
    physics = Physics(mesh)
    model = np.vstack([mesh.vertices[mesh.markers], mesh.nose])
    return physics, model, physics_layout_covariance(physics)


def _similarity(seed):
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    R = q * np.sign(np.linalg.det(q))
    return 1.07 * R, rng.normal(size=3) * 20.0


def test_covariance_is_symmetric_psd_with_a_rigid_nose(lips):
    _, model, cov = lips
    P = len(model)
    assert cov.shape == (3 * P, 3 * P)
    np.testing.assert_allclose(cov, cov.T, atol=1e-12)
    assert np.linalg.eigvalsh(cov).min() > -1e-9
    np.testing.assert_allclose(np.mean(np.diag(cov)[:-3]), 1.0)
    assert not cov[-3:].any() and not cov[:, -3:].any()


def test_a_moved_layout_is_predicted_exactly(lips):
    _, model, cov = lips
    A, t = _similarity(1)
    points = model @ A.T + t
    use = np.ones(len(model), bool)
    use[3] = False  # an unused marker is predicted from all the used ones
    pred = predict_layout_physics(model, points, use, cov)
    np.testing.assert_allclose(pred, points, atol=1e-8)


def test_the_spread_is_the_priors_schur_complement_turned_into_the_points_frame(lips):
    _, model, cov = lips
    A, t = _similarity(2)
    points = model @ A.T + t
    use = np.ones(len(model), bool)
    use[5] = False
    pred, loose = predict_layout_physics(model, points, use, cov, spread=True)
    np.testing.assert_allclose(pred, predict_layout_physics(model, points, use, cov), atol=1e-12)
    for i in (5, 11):                               # unused, and used (left out of its own prediction)
        others = np.flatnonzero(use & (np.arange(len(model)) != i))
        o = (3 * others[:, None] + np.arange(3)).ravel()
        own = 3 * i + np.arange(3)
        schur = cov[np.ix_(own, own)] - cov[np.ix_(own, o)] @ np.linalg.solve(
            cov[np.ix_(o, o)] + 0.01 * np.eye(len(o)), cov[np.ix_(o, own)])
        np.testing.assert_allclose(loose[i], A @ (schur + 0.01 * np.eye(3)) @ A.T, rtol=1e-7, atol=1e-10)
        assert np.linalg.eigvalsh(loose[i]).min() > 0


def test_equals_the_least_norm_force_reach(lips):
    physics, model, cov = lips
    P = len(model) - 1
    rng = np.random.default_rng(2)
    shift = np.vstack([rng.normal(size=(P, 3)), np.zeros((1, 3))])  # mm; the nose is rigid
    A, t = _similarity(3)
    points = (model + shift) @ A.T + t
    use = np.ones(P + 1, bool)
    pred = predict_layout_physics(model, points, use, cov, smoothing=1e-9, rounds=1)
    markers = np.asarray(physics.mesh.markers)
    for i in (0, 2, 12):
        others = np.flatnonzero(use & (np.arange(P + 1) != i))
        T = _similarity_3d(model[others], points[others])  # the first round's similarity
        back = np.linalg.solve(T[:3, :3], (points - T[:3, 3]).T).T
        seen = others[others < P]
        U, _ = physics.reach(
            node_dofs(markers[seen], "xyz", physics.n_nodes), (back[seen] - model[seen]).ravel()
        )
        expect = T[:3, :3] @ (model[i] + U[markers[i]]) + T[:3, 3]
        np.testing.assert_allclose(pred[i], expect, atol=1e-5)


def test_bad_input_is_named(lips):
    _, model, cov = lips
    use = np.ones(len(model), bool)
    with pytest.raises(ValueError, match="covariance"):
        predict_layout_physics(model, model, use, cov[:-3, :-3])
    with pytest.raises(ValueError, match="smoothing"):
        predict_layout_physics(model, model, use, cov, smoothing=0.0)
    with pytest.raises(ValueError, match="use must be"):
        predict_layout_physics(model, model, use[:-1], cov)
    bad = model.copy()
    bad[0] = np.nan
    with pytest.raises(ValueError, match="finite where use"):
        predict_layout_physics(model, bad, use, cov)


def test_predict_layout_takes_the_prior_as_an_option(lips):
    from lipgen.recon.firstframe import predict_layout

    _, model, cov = lips
    rng = np.random.default_rng(4)
    A, t = _similarity(5)
    points = (model + np.vstack([rng.normal(size=(len(model) - 1, 3)), np.zeros((1, 3))])) @ A.T + t
    use = np.ones(len(model), bool)
    with_prior = predict_layout(model, points, use, 5.0, covariance=cov)
    np.testing.assert_array_equal(with_prior, predict_layout_physics(model, points, use, cov))
    assert np.abs(with_prior - predict_layout(model, points, use, 5.0)).max() > 0.1


def test_rows_without_a_layout_are_predicted_nan(lips):
    _, model, cov = lips
    holed = model.copy()
    holed[5] = np.nan
    use = np.all(np.isfinite(holed), axis=1)
    pred = predict_layout_physics(holed, model, use, cov)
    assert np.isnan(pred[5]).all() and np.isfinite(np.delete(pred, 5, axis=0)).all()


def test_the_tracker_checks_the_layout_covariance_before_any_frame():
    from lipgen.recon.settings import ReconstructSettings
    from lipgen.recon.steps import track_raw_frames

    def frames():
        raise AssertionError("a frame was read")
        yield

    expected = np.zeros((2, 5, 2))
    with pytest.raises(ValueError, match=r"layout_covariance must have shape \(15, 15\)"):
        track_raw_frames(frames(), None, expected, ReconstructSettings(), rest_points=np.zeros((5, 3)),
                         layout_covariance=np.eye(12))
    with pytest.raises(ValueError, match="needs rest_points"):
        track_raw_frames(frames(), None, expected, ReconstructSettings(), layout_covariance=np.eye(15))
