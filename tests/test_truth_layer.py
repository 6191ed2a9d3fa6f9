"""The truth's nonlinear tissue layer: closed forms, the linear limit, monotone energy, and
measured departures from linear theory."""

import numpy as np
import pytest

from lipgen.mesh.procedural import lip_mesh
from lipgen.subject.layer import stvk_energy_density
from lipgen.subject.layer_build import build_layer


@pytest.fixture(scope="module")
def small():
    m = lip_mesh(0)
    return m, build_layer(m, np.ones(m.n_faces), np.full(m.n_nodes, 1.5), poisson=0.3, kappa_ratio=2.0)


def _affine_energy(layer, A):
    x = layer.rest @ A.T
    return layer.energy_grad(x, np.zeros_like(x))[0]


def test_homogeneous_deformation_matches_the_closed_form(small):
    _, L = small
    mu, lam, kappa = L.mu[0], L.lam[0], L.kappa[0]
    V = L.volume.sum()
    rng = np.random.default_rng(0)
    for eps in (1e-3, 0.3):
        A = np.eye(3) + eps * rng.normal(size=(3, 3))
        want = V * (stvk_energy_density(A, mu, lam) + 0.5 * kappa * (np.linalg.det(A) - 1) ** 2)
        assert _affine_energy(L, A) == pytest.approx(want, rel=1e-10)


def test_small_strain_energy_is_linear_elasticity_and_large_strain_is_not(small):
    _, L = small
    mu, lam = L.mu[0], L.lam[0] + L.kappa[0]  # at rest the volume penalty adds to lambda
    V = L.volume.sum()
    G = np.array([[0.3, 0.1, 0.0], [0.05, -0.2, 0.1], [0.0, 0.2, 0.1]])

    def linear(eps):
        e = 0.5 * eps * (G + G.T)
        return V * (mu * np.sum(e * e) + 0.5 * lam * np.trace(e) ** 2)

    small_ratio = _affine_energy(L, np.eye(3) + 1e-4 * G) / linear(1e-4)
    large_ratio = _affine_energy(L, np.eye(3) + 1.0 * G) / linear(1.0)
    assert small_ratio == pytest.approx(1.0, abs=1e-3)
    assert abs(large_ratio - 1.0) > 0.05  # measured: the geometric nonlinearity at 20-30 % strain


def test_the_solver_agrees_with_the_linear_solve_for_small_loads_and_not_for_large(small):
    from scipy.sparse.linalg import spsolve

    m, L = small
    f = np.zeros_like(L.rest)
    k = m.marker_index("corner_left")
    f[k] = [0.02, 0.01, -0.005]
    free = ~L.fixed
    dof = np.repeat(free, 3)
    lin = np.zeros_like(L.rest)
    lin[free] = spsolve(L.K0[dof][:, dof].tocsc(), f[free].ravel()).reshape(-1, 3)
    energies = []
    x = L.solve(1e-3 * f, L.rest, callback=energies.append, tol=1e-12)
    u = (x - L.rest) / 1e-3
    assert np.linalg.norm(u - lin) / np.linalg.norm(lin) < 2e-3
    big = L.solve(200 * f, L.rest, callback=energies.append)
    rel = np.linalg.norm((big - L.rest) - 200 * lin) / np.linalg.norm(200 * lin)
    print(f"large load: {np.linalg.norm(200 * lin[k]):.2f} mm linear, relative difference {rel:.3f}")
    assert rel > 0.05
    assert np.all(np.diff(energies[: L.iterations[0]]) <= 0)
    assert np.all(np.diff(energies[L.iterations[0]:]) <= 0)


def _volume_ratios(L, x):
    t = L.tets
    Ds = np.stack([x[t[:, k]] - x[t[:, 0]] for k in (1, 2, 3)], axis=-1)
    return np.linalg.det(Ds) / 6.0 / L.volume


def test_squeezed_lips_keep_their_volume():
    m = lip_mesh(0)
    n = m.n_nodes
    lips = np.zeros(n, bool)
    lips[m.region_nodes("lip")] = True
    out = {}
    for name, nu, kappa in (("incompressible", 0.45, 20.0), ("compressible", 0.0, 0.0)):
        L = build_layer(m, np.ones(m.n_faces), np.full(m.n_nodes, 1.5), poisson=nu, kappa_ratio=kappa)
        f = np.zeros_like(L.rest)
        f[:n][lips, 0] = -0.5 * m.vertices[lips, 0] / 25.0  # the corners pulled in (a pucker)
        f[n:][lips, 0] = f[:n][lips, 0]
        x = L.solve(f, L.rest)
        assert np.ptp(x[:n][lips, 0]) < 0.97 * np.ptp(L.rest[:n][lips, 0])  # it was squeezed
        out[name] = np.mean(np.abs(_volume_ratios(L, x) - 1.0))
    print(out)
    assert out["incompressible"] < 0.3 * out["compressible"]


def test_contact_keeps_the_lips_from_crossing():
    from lipgen.subject.motion import _contact_pairs

    m = lip_mesh(0)
    pairs = _contact_pairs(m)
    L = build_layer(m, np.ones(m.n_faces), np.full(m.n_nodes, 1.0), contact_pairs=pairs,
                    contact_stiffness=200.0)
    f = np.zeros_like(L.rest)
    f[pairs[:, 0], 1] = -0.4  # the upper lip pushed down
    f[pairs[:, 1], 1] = 0.4  # the lower lip pushed up
    free = ~L.fixed
    dof = np.repeat(free, 3)
    from scipy.sparse.linalg import spsolve

    K = build_layer(m, np.ones(m.n_faces), np.full(m.n_nodes, 1.0)).K0
    lin = np.zeros_like(L.rest)
    lin[free] = spsolve(K[dof][:, dof].tocsc(), f[free].ravel()).reshape(-1, 3)
    crossed_lin = (L.rest + lin)[pairs[:, 0], 1] - (L.rest + lin)[pairs[:, 1], 1]
    assert crossed_lin.min() < -1.0  # without contact they would cross by more than a millimetre
    x = L.solve(f, L.rest)
    gap = x[pairs[:, 0], 1] - x[pairs[:, 1], 1]
    assert gap.min() > -0.05


def test_bad_layers_are_refused():
    m = lip_mesh(0)
    with pytest.raises(ValueError, match="poisson"):
        build_layer(m, np.ones(m.n_faces), np.ones(m.n_nodes), poisson=0.5)
    with pytest.raises(ValueError, match="positive"):
        build_layer(m, np.ones(m.n_faces), np.zeros(m.n_nodes))
    L = build_layer(m, np.ones(m.n_faces), np.ones(m.n_nodes))
    f = np.zeros_like(L.rest)
    for kwargs, word in (({"maxiter": 0}, "maxiter"), ({"maxiter": 2.5}, "maxiter"), ({"tol": 0.0}, "tol"),
                         ({"tol": float("nan")}, "tol"), ({"x0": L.rest[:5]}, "x0")):
        with pytest.raises(ValueError, match=word):
            L.solve(f, L.rest, **kwargs)
    with pytest.raises(ValueError, match=r"force must be \(\d+, 3\)"):
        L.solve(f[:, :2], L.rest)


def test_the_layered_subject_moves_like_its_calibration_and_unlike_the_linear_model():
    from lipgen.subject.activation import ACTIONS
    from lipgen.subject.motion import ACTION_TARGETS_MM, default_subject, simulate
    from lipgen.subject.truth import with_layer

    linear = default_subject(0, subject_seed=1)
    layered = with_layer(linear)
    A = np.zeros((3, len(ACTIONS)))
    a = ACTIONS.index("lip_corner_puller_left")
    A[:, a] = [0.01, 1.0, 1.8]
    lin, non = simulate(linear, A), simulate(layered, A)
    marker = layered.mesh.marker_index(ACTION_TARGETS_MM["lip_corner_puller_left"][0])
    small = np.linalg.norm(non.displacements[0, marker]) / 0.01
    assert small == pytest.approx(np.linalg.norm(linear.responses[a, marker]), rel=0.02)  # calibrated
    d_lin, d_non = lin.displacements[2], non.displacements[2]
    rel = np.linalg.norm(d_non - d_lin) / np.linalg.norm(d_lin)
    print(f"1.8 x corner puller: nonlinear layer vs linear subject differ by {rel:.2f} (relative)")
    assert rel > 0.1


def test_a_free_layer_takes_the_shape_of_its_active_strain():
    """Closed form: with nothing held, the layer relaxes to ``x = Fa X`` (zero energy, zero force);
    the active strain keeps the volume (det Fa = 1) and is measured by the energy elsewhere."""
    from lipgen.subject.layer import active_strain

    m = lip_mesh(0)
    L = build_layer(m, np.ones(m.n_faces), np.full(m.n_nodes, 1.5), poisson=0.4, kappa_ratio=50.0,
                    anchors=np.zeros(0, np.int64))
    f = np.array([0.8, 0.0, 0.6])
    inv = active_strain(np.tile(f, (len(L.tets), 1)), np.full(len(L.tets), 0.3))
    Fa = np.linalg.inv(inv[0])
    assert np.linalg.det(Fa) == pytest.approx(1.0, abs=1e-12)
    assert f @ Fa @ f == pytest.approx(np.exp(-0.3), rel=1e-12)  # the fibres shorten by exp(-c)
    zero = np.zeros_like(L.rest)
    e, g = L.energy_grad(L.rest @ Fa.T, zero, active=inv)
    e_rest, g_rest = L.energy_grad(L.rest, zero, active=inv)
    assert e == pytest.approx(0.0, abs=1e-12 * e_rest) and e_rest > 0
    assert np.abs(g).max() < 1e-9 * np.abs(g_rest).max()


@pytest.fixture(scope="module")
def pucker_subject():
    from lipgen.subject.motion import default_subject
    from lipgen.subject.truth import with_layer

    return with_layer(default_subject(5, subject_seed=5))  # seeds 0-4 and 100 were looked at


def _lip_measures(subject, x):
    """Lip (vermilion) layer: volume ratio, area-weighted thickness ratio (prism volume over mean
    face area), and mouth width ratio."""
    L, m = subject.layer, subject.mesh
    n, F = m.n_nodes, m.faces
    lip = np.isin(np.array(m.region_names)[m.regions], ("lip", "ridge"))

    def area(X):
        return 0.5 * np.linalg.norm(np.cross(X[F[:, 1]] - X[F[:, 0]], X[F[:, 2]] - X[F[:, 0]]), axis=1)

    vol = (_volume_ratios(L, x) * L.volume).reshape(3, -1).sum(axis=0)[lip]
    vol0 = L.volume.reshape(3, -1).sum(axis=0)[lip]
    mid, mid0 = 0.5 * (area(x[:n]) + area(x[n:])), 0.5 * (area(L.rest[:n]) + area(L.rest[n:]))
    thick = (vol / mid[lip]) / (vol0 / mid0[lip])
    cl, cr = m.marker_index("corner_left"), m.marker_index("corner_right")
    width = np.linalg.norm(x[cl] - x[cr]) / np.linalg.norm(L.rest[cl] - L.rest[cr])
    return vol.sum() / vol0.sum(), float(np.sum(mid0[lip] * thick) / mid0[lip].sum()), width


def test_a_pucker_thickens_the_lips_at_nearly_constant_volume(pucker_subject):
    """The orbicularis contraction of a full pucker narrows the mouth and thickens the lip layer
    while its volume stays within 3 %; the same marker displacement made by a surface pull alone
    (the truth before the contraction) leaves its thickness nearly unchanged (measured on seed 5:
    +6.2 % against +0.3 %, volume -1.3 % and -1.5 %)."""
    from lipgen.subject.activation import ACTIONS, action_index
    from lipgen.subject.motion import ACTION_TARGETS_MM
    from lipgen.subject.truth import layer_active

    s = pucker_subject
    L, n = s.layer, s.mesh.n_nodes
    a = action_index("pucker")
    k = s.mesh.marker_index(ACTION_TARGETS_MM["pucker"][0])
    A = np.zeros(len(ACTIONS))
    A[a] = 0.01
    small = L.solve(np.vstack([0.01 * s.layer_forces[a], np.zeros((n, 3))]), L.rest, tol=1e-10,
                    active=layer_active(s, A))
    assert np.linalg.norm(small[k] - L.rest[k]) / 0.01 == pytest.approx(
        np.linalg.norm(s.responses[a, k]), rel=0.02)  # calibrated in the small-strain limit
    A[a] = 1.0
    x = L.solve(np.vstack([s.layer_forces[a], np.zeros((n, 3))]), L.rest, active=layer_active(s, A))
    vol, thick, width = _lip_measures(s, x)
    # the surface pull alone, scaled to the same small-strain displacement of the marker
    f = np.vstack([s.layer_forces[a], np.zeros((n, 3))])
    u = np.zeros_like(L.rest)
    u[~L.fixed] = L._factor()(f[~L.fixed].ravel()).reshape(-1, 3)
    f *= np.linalg.norm(s.responses[a, k]) / np.linalg.norm(u[k])
    vol_pull, thick_pull, width_pull = _lip_measures(s, L.solve(f, L.rest))
    print(f"pucker 1: volume {vol:.4f}, thickness {thick:.4f}, width {width:.4f}; surface pull alone: "
          f"volume {vol_pull:.4f}, thickness {thick_pull:.4f}, width {width_pull:.4f}")
    assert width < 0.9 and width_pull < 0.95  # both narrow the mouth
    assert abs(vol - 1.0) < 0.03
    assert thick > 1.02
    assert thick - thick_pull > 0.03


def test_the_lbfgs_direction_meets_the_secant_condition():
    from lipgen.subject.layer import _lbfgs_direction

    rng = np.random.default_rng(0)
    Q = rng.normal(size=(8, 8))
    H = Q @ Q.T + 8 * np.eye(8)            # a quadratic's Hessian
    D = np.diag(np.diag(H))                 # the initial inverse Hessian's matrix
    solve = lambda r: np.linalg.solve(D, r)  # noqa: E731
    g = rng.normal(size=8)
    assert np.allclose(_lbfgs_direction(g, [], solve), solve(g))
    memory = []
    for _ in range(4):
        s = rng.normal(size=8)
        y = H @ s
        memory.append((s, y, 1.0 / float(s @ y)))
        assert np.allclose(_lbfgs_direction(y, memory, solve), s)  # the newest pair, exactly


def test_the_solver_stops_near_the_equilibrium_of_a_large_load(small):
    """The default tolerance (1e-4 mm steps) against a solve to 1e-9 mm, and the gradient there."""
    m, L = small
    f = np.zeros_like(L.rest)
    f[m.marker_index("corner_left")] = [4.0, 2.0, -1.0]   # millimetres of motion, far from linear
    x = L.solve(f, L.rest)
    tight = L.solve(f, L.rest, tol=1e-9, maxiter=400)
    assert np.abs(x - L.rest).max() > 1.0
    assert np.abs(x - tight).max() < 1e-3
    g = L.energy_grad(tight, f)[1][~L.fixed]
    assert np.abs(g).max() < 1e-6 * np.abs(f).max()


def test_the_layers_truth_does_not_depend_on_the_blas_thread_count(pucker_subject):
    """The solver's supernodal factorisations (CHOLMOD's BLAS) would round differently on two
    threads: the layer runs on one, always, so a dataset's truth does not depend on the machine."""
    from lipgen._threads import blas_threads
    from lipgen.subject.activation import ACTIONS, action_index
    from lipgen.subject.truth import layer_displacements

    A = np.zeros((3, len(ACTIONS)))
    A[:, action_index("jaw_open")] = [0.3, 0.8, 0.5]
    A[:, action_index("pucker")] = [0.0, 0.6, 1.0]
    with blas_threads(1, always=True):
        one = layer_displacements(pucker_subject, A)
    with blas_threads(2, always=True):
        two = layer_displacements(pucker_subject, A)
    assert np.abs(one).max() > 1.0 and one.tobytes() == two.tobytes()


def test_without_cvxopt_the_layer_reaches_the_same_equilibria(pucker_subject, monkeypatch):
    """SuperLU in a stored order stands in for CHOLMOD where cvxopt is not installed: the same
    steps, the same equilibria to rounding (the factorisations differ only in their last bits)."""
    import lipgen.fem.solver
    from lipgen.subject.activation import ACTIONS, action_index
    from lipgen.subject.truth import layer_displacements

    A = np.zeros((2, len(ACTIONS)))
    A[:, action_index("jaw_open")] = [0.4, 0.9]
    A[:, action_index("lip_corner_puller_left")] = [0.5, 1.2]
    layer = pucker_subject.layer
    layer.cache.pop("cholesky", None)
    fast = layer_displacements(pucker_subject, A)
    steps = list(layer.iterations[-2:])
    monkeypatch.setattr(lipgen.fem.solver, "cholmod_available", lambda: False)
    layer.cache.pop("cholesky", None)
    slow = layer_displacements(pucker_subject, A)
    assert layer.cache["cholesky"].method == "superlu"
    assert layer.iterations[-2:] == steps
    assert np.abs(fast - slow).max() < 1e-8 and np.abs(fast).max() > 1.0
    layer.cache.pop("cholesky", None)


def test_a_tangent_that_fails_to_factorise_falls_back_to_the_rest_stiffness(small, monkeypatch, caplog):
    """A tangent that is not positive definite (rounding, in principle) is not solved: the step
    starts from K0 instead, with a warning, and the solver still reaches the equilibrium."""
    from lipgen.subject.layer_stiffness import PatternCholesky

    _, L = small
    f = np.zeros_like(L.rest)
    f[~L.fixed] = 0.3 * np.random.default_rng(5).normal(size=((~L.fixed).sum(), 3))
    want = L.solve(f, L.rest, tol=1e-9)

    def refuse(self, A):
        raise np.linalg.LinAlgError("the matrix is not positive definite (a test)")

    monkeypatch.setattr(PatternCholesky, "factor", refuse)
    L.cache.pop("last", None)
    with caplog.at_level("WARNING", logger="lipgen.subject.layer"):
        got = L.solve(f, L.rest, tol=1e-9, maxiter=1000)
    assert "starts from the rest stiffness" in caplog.text and "no equilibrium" not in caplog.text
    assert np.abs(got - want).max() < 1e-6 < np.abs(want - L.rest).max()
    L.cache.pop("last", None)


def test_the_factorisation_can_be_chosen_and_a_bad_choice_is_refused(small):
    _, L = small
    f = np.zeros_like(L.rest)
    f[~L.fixed] = 0.2
    L.use_factorisation("superlu")
    lu = L.solve(f, L.rest)
    assert L.cache["cholesky"].method == "superlu"
    L.use_factorisation("auto")
    assert "cholesky" not in L.cache and "last" not in L.cache
    assert np.abs(L.solve(f, L.rest) - lu).max() < 1e-8
    with pytest.raises(ValueError, match="method must be one of"):
        L.use_factorisation("lu")
