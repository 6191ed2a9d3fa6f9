"""lipgen.blender, the add-on's data side, without Blender: modes, physics cache, forces, curves."""

import numpy as np
import pytest

from lipgen import SingularStiffnessError, TopologyMismatchError, lip_mesh
from lipgen.blender import (
    CoefficientCurves,
    ForceResponses,
    ModeBasis,
    PhysicsSpec,
    clear_physics_cache,
    force_field,
    load_curves,
    moved_nodes,
    physics_for,
    reach_goals,
)
from lipgen.blender.physics_cache import MAX_CACHED, cached_count
from lipgen.fem import DEFAULT_STIFFNESS, Physics, dofs
from lipgen.modes.model import ModeModel


@pytest.fixture(scope="module")
def mesh():
    return lip_mesh(0)


@pytest.fixture(scope="module")
def physics(mesh):
    return Physics(mesh)


@pytest.fixture(scope="module")
def model(mesh, physics):
    rng = np.random.default_rng(0)
    F = np.zeros((30, mesh.n_nodes, 3))
    for f in range(30):
        F[f, rng.choice(mesh.markers, 3, replace=False)] = rng.normal(size=(3, 3))
    return ModeModel(5).fit(physics.displace(F), mesh=mesh)


def _spec(mesh, **kw):
    args = dict(vertices=mesh.vertices, faces=mesh.faces, regions=mesh.regions, anchors=mesh.anchors,
                stiffness=tuple(DEFAULT_STIFFNESS.items()))
    args.update(kw)
    return PhysicsSpec(**args)


# ---- modes --------------------------------------------------------------------------------------
def test_mode_basis_from_model_reproduces_synthesize(model):
    basis = ModeBasis.from_model(model)
    rng = np.random.default_rng(1)
    coef = rng.normal(size=(4, 5)) * np.sqrt(model.explained_variance_)
    assert np.allclose(basis.displacement(coef), model.synthesize(coef), atol=1e-12)
    # What the rig stores: slider * offset == coefficient * component.
    rig = basis.mean + np.einsum("fk,knc->fnc", basis.sliders(coef), basis.offsets())
    assert np.allclose(rig, model.synthesize(coef), atol=1e-12)
    assert np.allclose(basis.coefficients(basis.sliders(coef)), coef)
    assert np.allclose(basis.scales, np.sqrt(model.explained_variance_))
    assert basis.topology_id == model.topology_id_


def test_mode_basis_as_model_feeds_usd_export_arrays(model, mesh):
    from lipgen.usd.export import _mode_arrays

    basis = ModeBasis.from_model(model)
    mean, comps, std = _mode_arrays(mesh, basis.as_model())
    assert np.allclose(mean, basis.mean) and np.allclose(comps, basis.components)
    assert np.allclose(std, basis.scales)


def test_mode_basis_refuses_other_topology(model):
    basis = ModeBasis.from_model(model)
    with pytest.raises(TopologyMismatchError, match="topology"):
        basis.check_topology("0000000000000000", "the object")
    basis.check_topology(model.topology_id_)


def test_mode_basis_validates():
    with pytest.raises(ValueError, match="scales must be positive"):
        ModeBasis(np.zeros((3, 3)), np.zeros((1, 3, 3)), [0.0], ("a",))
    with pytest.raises(ValueError, match=r"mean must have shape \(3, 3\)"):
        ModeBasis(np.zeros((4, 3)), np.zeros((1, 3, 3)), [1.0], ("a",))
    with pytest.raises(ValueError, match="names has 2 entries for 1 modes"):
        ModeBasis(np.zeros((3, 3)), np.zeros((1, 3, 3)), [1.0], ("a", "b"))


def test_physics_modes_are_softest_eigenvectors(physics, mesh):
    basis = ModeBasis.from_physics(physics, 4)
    free = physics.free_dofs
    Kff = physics.K[free][:, free].toarray()
    lam, vec = np.linalg.eigh(Kff)
    C = basis.components.reshape(4, -1)
    assert np.allclose(C @ C.T, np.eye(4), atol=1e-10)
    for i in range(4):
        assert abs(abs(C[i, free] @ vec[:, i]) - 1.0) < 1e-8
        assert np.abs(C[i, physics.anchored_dofs]).max() == 0.0
    peaks = np.linalg.norm(basis.offsets(), axis=2).max(axis=1)
    assert np.allclose(peaks, 1.0)  # a slider unit moves the mode's largest vertex by 1 mm
    with pytest.raises(ValueError, match="n_modes must be in"):
        ModeBasis.from_physics(physics, 10**6)


def test_fit_passes_topology(mesh, physics):
    rng = np.random.default_rng(3)
    U = physics.displace(rng.normal(size=(6, mesh.n_nodes, 3)))
    basis = ModeBasis.fit(U, 3, mesh=mesh)
    assert basis.topology_id == mesh.topology_id and basis.n_modes == 3


# ---- physics cache ------------------------------------------------------------------------------
def test_physics_cache_hits_by_content(mesh):
    clear_physics_cache()
    a = physics_for(_spec(mesh))
    b = physics_for(_spec(mesh, vertices=mesh.vertices.copy()))
    assert a is b and cached_count() == 1
    stiffer = dict(DEFAULT_STIFFNESS, lip=3.0)
    c = physics_for(_spec(mesh, stiffness=tuple(stiffer.items())))
    assert c is not a
    moved = mesh.vertices.copy()
    moved[0, 0] += 1e-9
    assert physics_for(_spec(mesh, vertices=moved)) is not a
    for i in range(MAX_CACHED):
        physics_for(_spec(mesh, poisson=0.02 + 0.01 * i))
    assert cached_count() == MAX_CACHED
    assert physics_for(_spec(mesh)) is not a  # evicted, rebuilt
    clear_physics_cache()
    assert cached_count() == 0


def test_physics_cache_passes_core_errors(mesh):
    with pytest.raises(SingularStiffnessError):
        physics_for(_spec(mesh, anchors=np.zeros(0, np.int64)))
    with pytest.raises(ValueError, match="unknown region"):
        _spec(mesh, stiffness=(("lips", 1.0),))
    with pytest.raises(ValueError, match="positive"):
        _spec(mesh, stiffness=(("lip", -1.0),))


# ---- forces and reach -----------------------------------------------------------------------------
def test_force_responses_are_the_displacement_of_the_force(mesh, physics):
    nodes = mesh.markers[[0, 3, 7]]
    normals = mesh.vertex_normals()
    resp = ForceResponses(physics, nodes, normals)
    for direction in ([0, 0, 1], [1, -2, 0.5]):
        F = force_field(mesh.n_nodes, nodes, 0.8, direction=direction)
        assert np.allclose(resp.displacement(0.8, direction), physics.displace(F), atol=1e-12)
    F = force_field(mesh.n_nodes, nodes, -0.3, normals=normals)
    assert np.allclose(resp.displacement(-0.3), physics.displace(F), atol=1e-12)
    assert np.allclose(np.linalg.norm(F[nodes], axis=1), 0.3)


def test_force_field_checks_its_input(mesh):
    with pytest.raises(ValueError, match="non-zero"):
        force_field(mesh.n_nodes, [1], 1.0, direction=[0, 0, 0])
    with pytest.raises(ValueError, match="exactly one"):
        force_field(mesh.n_nodes, [1], 1.0)
    with pytest.raises(ValueError, match="must not be empty"):
        force_field(mesh.n_nodes, [], 1.0, direction=[0, 0, 1])


def test_reach_goals_match_physics_reach(mesh, physics):
    rest = mesh.vertices
    target = rest.copy()
    target[mesh.markers[2]] += [0.0, 1.0, 0.5]
    target[mesh.anchors[0]] += [1.0, 0.0, 0.0]  # an anchor cannot be a goal
    moved = moved_nodes(rest, target, 1e-6)
    goals = reach_goals(rest, target, np.append(moved, mesh.markers[5]), mesh.anchors)
    assert list(goals.skipped_anchors) == [mesh.anchors[0]]
    assert sorted(goals.nodes) == sorted([mesh.markers[2], mesh.markers[5]])
    U, _ = physics.reach(goals.dofs, goals.values)
    assert np.allclose(U[mesh.markers[2]], [0.0, 1.0, 0.5], atol=1e-8)
    assert np.allclose(U[mesh.markers[5]], 0.0, atol=1e-8)  # held in place
    assert np.array_equal(goals.dofs, dofs(goals.nodes))
    with pytest.raises(ValueError, match="no reach goal"):
        reach_goals(rest, target, mesh.anchors[:2], mesh.anchors)


# ---- curves -------------------------------------------------------------------------------------
def test_curves_from_csv_and_npz(tmp_path):
    csv = tmp_path / "c.csv"
    csv.write_text("# exported\ntime,jaw,smile\n0.0,1,2\n0.5,3,4\n\n1.0,5,6\n")
    c = load_curves(csv)
    assert c.names == ("jaw", "smile") and c.coefficients.shape == (3, 2)
    assert np.allclose(c.frame_numbers(24, 1), [1, 13, 25])
    np.savez(tmp_path / "f.npz", coef=np.arange(6.0).reshape(3, 2), frames=[10, 12, 20])
    assert np.allclose(load_curves(tmp_path / "f.npz").frame_numbers(24, 1), [10, 12, 20])
    np.savez(tmp_path / "p.npz", coefficients=np.ones((4, 3)), fps=np.float64(8))
    assert np.allclose(load_curves(tmp_path / "p.npz").frame_numbers(24, 1), [1, 4, 7, 10])
    assert np.allclose(CoefficientCurves(np.ones((3, 1))).frame_numbers(24, 5), [5, 6, 7])


@pytest.mark.parametrize("text, match", [
    ("1,2\n3,4\n", "first row must be a header"),
    ("frame,a\n1,2\n3\n", "line 3: 1 values, but the header has 2"),
    ("frame,a\n1,x\n", "line 2: not a number"),
    ("frame,a\n2,1\n1,1\n", "frames must increase"),
    ("frame\n1\n", "no coefficient columns"),
    ("frame,a\n", "at least one data row"),
])
def test_bad_csv_is_named(tmp_path, text, match):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(ValueError, match=match):
        load_curves(p)


def test_bad_npz_is_named(tmp_path):
    np.savez(tmp_path / "w.npz", weights=np.ones((2, 2)))
    with pytest.raises(ValueError, match=r"expected one of \('coefficients', 'coef'\)"):
        load_curves(tmp_path / "w.npz")
    with pytest.raises(FileNotFoundError):
        load_curves(tmp_path / "missing.npz")
    (tmp_path / "x.json").write_text("{}")
    with pytest.raises(ValueError, match="use .npz or .csv"):
        load_curves(tmp_path / "x.json")


# ---- speech -------------------------------------------------------------------------------------
def test_project_inverts_displacement(model):
    basis = ModeBasis.from_model(model)
    coef = np.array([[1.0, -2.0, 0.5, 0.0, 3.0], [0.0, 0.0, 0.0, 0.0, 0.0]])
    assert np.allclose(basis.project(basis.displacement(coef)), coef, atol=1e-10)
    assert np.allclose(basis.project(basis.displacement(coef[0])), coef[0], atol=1e-10)
    assert np.allclose(basis.project(basis.displacement(coef)), model.project(model.synthesize(coef)))
    with pytest.raises(ValueError, match="must end in"):
        basis.project(np.zeros((3, 3)))


def test_speech_on_the_procedural_lips(mesh):
    from lipgen.blender.speech import lips_resolution, performer, speech_displacements
    from lipgen.subject.activation import viseme_activations

    assert lips_resolution(mesh.n_nodes, mesh.topology_id) == 0
    r1 = lip_mesh(1)
    assert lips_resolution(r1.n_nodes, r1.topology_id) == 1
    assert lips_resolution(mesh.n_nodes, "not-a-topology") is None
    assert lips_resolution(123, mesh.topology_id) is None
    U = speech_displacements("AA:0.3 M:0.2", 24.0, 0)
    assert U.shape == (len(viseme_activations("AA:0.3 M:0.2", fps=24.0)), mesh.n_nodes, 3)
    # Node i of the resolution-0 rig moves as node i of the performer's finer mesh.
    full = performer(0).displacements(viseme_activations("AA:0.3 M:0.2", fps=24.0))
    assert np.array_equal(U, full[:, : mesh.n_nodes]) and np.abs(U).max() > 2.0
    with pytest.raises(ValueError):
        speech_displacements("NOT_A_VISEME", 24.0, 0)


def test_force_as_peak_displacement(mesh, physics):
    nodes = mesh.markers[[1, 4]]
    resp = ForceResponses(physics, nodes, mesh.vertex_normals())
    U = resp.displacement(-2.5, [0, 1, 0], peak=True)
    assert np.isclose(np.linalg.norm(U, axis=1).max(), 2.5)
    scale = resp.force_scale(-2.5, [0, 1, 0], peak=True)
    F = force_field(mesh.n_nodes, nodes, scale, direction=[0, 1, 0])
    assert np.allclose(U, physics.displace(F), atol=1e-12)
    anchored = ForceResponses(physics, mesh.anchors[:3], mesh.vertex_normals())
    with pytest.raises(ValueError, match="moves no vertex"):
        anchored.displacement(1.0, [0, 0, 1], peak=True)
