"""The physics covariance (eq 4.5), the thesis's "full-circle link" and the combined model (§6.1)."""

import functools

import numpy as np
import pytest

from lipgen import Physics, dofs, lip_mesh
from lipgen.modes.combined import CombinedModel, default_residual_variance
from lipgen.modes.llse import LLSE, LowRankCovariance, PhysicsCovariance, SumCovariance
from lipgen.modes.model import ModeModel
from lipgen.subject.motion import ACTIONS, default_subject, random_activations, simulate


@pytest.fixture(scope="module")
def physics():
    return Physics(lip_mesh(0))


def _dense_K_inv_sq(physics):
    """K_s^-2 embedded in 3n x 3n, from a dense inverse (test-only reference)."""
    free = physics.free_dofs
    Kinv = np.linalg.inv(physics.K_s.toarray())
    out = np.zeros((physics.n_dofs, physics.n_dofs))
    out[np.ix_(free, free)] = Kinv @ Kinv
    return out


def test_min_strain_equals_llse_under_physics_covariance(physics):
    mesh = physics.mesh
    rng = np.random.default_rng(0)
    for nodes, axes in ((mesh.markers, "xyz"), (mesh.markers[:8], "xyz"), (mesh.markers, "yz")):
        d = dofs(nodes, axes)
        goals = rng.normal(scale=2.0, size=(3, len(d)))
        U_reach, _ = physics.reach(d, goals)
        U_llse = LLSE.build(PhysicsCovariance(physics), d)(goals)
        assert np.allclose(U_llse, U_reach, atol=1e-9 * np.abs(U_reach).max())


def test_energy_prior_gives_least_strain_energy_field(physics):
    """Under Λ = K_s^-1 the LLSE is argmin UᵀKU with U[o] = y: U[h] = -K_hh^-1 K_ho y."""
    d = dofs(physics.mesh.markers, "xy")
    y = np.random.default_rng(3).normal(size=len(d))
    U = LLSE.build(PhysicsCovariance(physics, 0.7, kind="energy"), d)(y).ravel()
    K = physics.K.toarray()
    h = np.setdiff1d(physics.free_dofs, d)
    want = -np.linalg.solve(K[np.ix_(h, h)], K[np.ix_(h, d)] @ y)
    assert np.allclose(U[d], y, atol=1e-9) and np.allclose(U[h], want, atol=1e-8 * np.abs(want).max())
    assert np.allclose(U[physics.anchored_dofs], 0)
    blocks = PhysicsCovariance(physics, 0.7, kind="energy").diag_blocks([5, 77])
    Kinv = np.zeros_like(K)
    Kinv[np.ix_(physics.free_dofs, physics.free_dofs)] = np.linalg.inv(physics.K_s.toarray())
    assert np.allclose(blocks, 0.7 * np.stack([Kinv[15:18, 15:18], Kinv[231:234, 231:234]]))


def test_physics_covariance_matches_dense_reference(physics):
    ref = _dense_K_inv_sq(physics)
    cov = PhysicsCovariance(physics, scale=2.5)
    d = dofs(physics.mesh.markers[:5])
    assert np.allclose(cov.columns(d), 2.5 * ref[:, d], rtol=1e-9, atol=1e-12 * np.abs(ref).max())
    nodes = np.array([3, 40, 150])
    blocks = np.stack([ref[3 * i:3 * i + 3, 3 * i:3 * i + 3] for i in nodes])
    assert np.allclose(cov.diag_blocks(nodes), 2.5 * blocks, rtol=1e-9, atol=1e-12 * np.abs(ref).max())
    # The posterior under the physics prior is PSD and zero at the goals.
    est = LLSE.build(cov, d)
    post = est.posterior_blocks(physics.mesh.markers[:5])
    assert np.allclose(post, 0, atol=1e-9 * np.abs(ref).max())


def test_woodbury_gain_equals_plain_llse(physics):
    """The structured gain for modes + physics equals eq 4.7 with the dense summed covariance."""
    rng = np.random.default_rng(1)
    free = physics.free_dofs
    B = np.zeros((4, physics.n_dofs))
    B[:, free] = rng.normal(size=(4, len(free)))
    phys = PhysicsCovariance(physics, scale=1e-2)
    d = dofs(physics.mesh.markers[:6])
    est = LLSE.build(SumCovariance(LowRankCovariance(B), phys), d, noise=0.05)
    Sig = B.T @ B + 1e-2 * _dense_K_inv_sq(physics)
    G = Sig[:, d] @ np.linalg.inv(Sig[np.ix_(d, d)] + 0.05 * np.eye(len(d)))
    y = rng.normal(size=len(d))
    assert np.allclose(est(y).ravel(), G @ y, atol=1e-9 * np.abs(G @ y).max())


def _outside_span_case(physics, noise_mm=0.0, seeds=(1, 2)):
    """Train without the smile and the funneler; test on frames that use them (Table 5.1's protocol,
    smaller). Returns the training reach fields, the test fields measured and true, and the true
    fields of the training frames."""
    mesh = physics.mesh
    subject = default_subject(0, resolution=1)
    held = [ACTIONS.index("lip_corner_puller"), ACTIONS.index("funneler")]
    train = random_activations(140, seed=seeds[0])
    train[:, held] = 0.0
    test = random_activations(90, seed=seeds[1])
    test = test[test[:, held].max(axis=1) > 0.3]
    n0, md = mesh.n_nodes, dofs(mesh.markers)
    rng = np.random.default_rng(7)

    def fields(act):
        motion = simulate(subject, act)
        goals = motion.markers - mesh.vertices[mesh.markers]
        goals = goals + rng.normal(scale=noise_mm, size=goals.shape) if noise_mm else goals
        U, _ = physics.reach(md, goals.reshape(len(act), -1))
        return U, motion.vertices[:, :n0] - mesh.vertices  # nested meshes: node i is node i

    U_train, _ = fields(train)
    U_test, truth = fields(test)
    return U_train, U_test, truth


@functools.cache
def _fitted(physics, noise_mm, seeds):
    """The case of :func:`_outside_span_case`, its 10 modes and its combined model, computed once per
    test process: the two tests that use the case at noise 0.3 mm, seeds (1, 101), share it. Every
    case asked for stays cached (16, about 0.6 MB each), which costs less than a smaller cache's
    bookkeeping."""
    U_train, U_test, truth = _outside_span_case(physics, noise_mm, seeds)
    modes = ModeModel(10).fit(U_train, mesh=physics.mesh)
    return modes, CombinedModel(modes, physics).fit(U_train), U_test, truth


def _errors(physics, modes, combined, U_test, truth, d, noise=0.0):
    """MSE per hidden DOF against the true surface of each estimator, from ``U_test[:, d]``; the
    learned-only and physics-only columns are given the true marker-noise variance ``noise``, the
    combined model uses its own estimate."""
    Y, X = truth.reshape(len(truth), -1), U_test.reshape(len(U_test), -1)
    hidden = np.setdiff1d(physics.free_dofs, d)  # the anchored DOFs are 0 in every estimate
    scale = {kind: default_residual_variance(modes, physics, 1.0, kind=kind) for kind in ("force", "energy")}
    err = {}
    for name, est in (("modes", modes.llse(d, noise=noise)), ("full", modes.llse(d, "full", noise=noise)),
                      *((f"physics_{k}", LLSE.build(PhysicsCovariance(physics, scale[k], k), d, noise=noise))
                        for k in ("force", "energy")),
                      ("combined", combined.mixture(d)), ("combined_fixed", combined.llse(d))):
        err[name] = np.mean((est(X[:, d]).reshape(len(Y), -1) - Y)[:, hidden] ** 2)
    return err


@pytest.mark.parametrize("noise_mm", [0.0, 0.3])
def test_combined_model_beats_both_on_motion_outside_the_training_span(physics, noise_mm):
    """8 random realisations of Table 5.1's held-out-action protocol (train without the smile and
    the funneler, test on frames that use them), exact markers and 0.3 mm marker noise; the
    combined model's prior kind and noise are chosen from each training set only, its residual
    variance is weighed per frame (``CombinedModel.mixture``). In every row its error is below the
    best learned-only (10 modes or full covariance, the better one in each realisation) and the
    best physics-only (K_s⁻² or K_s⁻¹) error on geometric average over the realisations, in this
    small configuration (no head motion). Per realisation it is not (x-y: 3 wins of 8 against the
    learned modes); see lipgen.modes.combined for the full experiment."""
    mesh = physics.mesh
    rows = {"xyz (8 points)": dofs(mesh.markers[:8]), "yz": dofs(mesh.markers, "yz"),
            "xy": dofs(mesh.markers, "xy")}
    ratios = {row: {"learned": [], "physics": []} for row in rows}
    for seed in range(8):
        modes, combined, U_test, truth = _fitted(physics, noise_mm, (seed, seed + 100))
        if noise_mm == 0:
            assert combined.noise_variance_ < 1e-3  # exact markers: (almost) no noise found
        for row, d in rows.items():
            err = _errors(physics, modes, combined, U_test, truth, d, noise_mm ** 2)
            ratios[row]["learned"].append(err["combined"] / min(err["modes"], err["full"]))
            ratios[row]["physics"].append(err["combined"] / min(err["physics_force"], err["physics_energy"]))
    bound = 0.95 if noise_mm == 0 else 1.0
    for row, r in ratios.items():
        for kind, values in r.items():
            assert np.exp(np.mean(np.log(values))) < bound, (row, kind, np.round(values, 3))
    assert sum(v < 1 for v in ratios["xyz (8 points)"]["physics"]) >= 7  # from 8 points: (almost) always


def test_combined_model_estimates_the_marker_noise(physics):
    """0.3 mm marker noise: the noise variance found from the training fields is near the truth
    (0.09 mm²). Which of the three estimates wins then changes from row to row and run to run
    (the Table 5.1 report), so that is not asserted here."""
    _, combined, _, _ = _fitted(physics, 0.3, (1, 101))
    assert 0.6 * 0.09 < combined.noise_variance_ < 1.3 * 0.09
    assert combined.selection_.log_likelihood == max(v["log_likelihood"]
                                                     for v in combined.selection_.by_kind.values())


def test_fit_from_markers_trains_on_least_strain_fields(physics):
    mesh = physics.mesh
    goals = np.random.default_rng(4).normal(size=(30, 16, 3))
    m = ModeModel(5).fit_from_markers(physics, goals)
    U, _ = physics.reach(dofs(mesh.markers), goals.reshape(30, -1))
    ref = ModeModel(5).fit(U)
    assert np.allclose(m.components_, ref.components_) and m.topology_id_ == mesh.topology_id
    with pytest.raises(ValueError, match=r"goals must have shape \(\*, 16, 3\)"):
        ModeModel(5).fit_from_markers(physics, goals[:, :8])
