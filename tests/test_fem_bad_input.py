"""Bad input to the physics: clear errors that name the value and say how to fix it."""

import numpy as np
import pytest
import scipy.sparse as sp
from _fem_cases import SOLVERS, bent_mesh, grid

from lipgen import SingularStiffnessError
from lipgen.errors import MeshError
from lipgen.fem import Physics, dofs, element_stiffness
from lipgen.fem.solver import factorize
from lipgen.mesh.lipmesh import LipMesh


@pytest.fixture(scope="module")
def physics():
    return Physics(bent_mesh(), {"lip": 1.0})


def test_no_anchors():
    V, F, _ = grid()
    with pytest.raises(SingularStiffnessError, match="no anchors.*anchors=\\[...\\]"):
        Physics(LipMesh(V, F))


def test_piece_not_attached_to_any_anchor_is_named():
    V, F, idx = grid(nx=4, ny=3)
    V2 = V + [10.0, 0, 0]
    mesh = LipMesh(np.r_[V, V2], np.r_[F, F + len(V)], anchors=idx[0, :3])
    with pytest.raises(SingularStiffnessError, match=r"12 of 24 nodes .* not connected .* nodes \[12, 13"):
        Physics(mesh)


@pytest.mark.parametrize("anchors", [[0], [7]])
def test_single_anchor_on_flat_sheet_leaves_a_free_rotation(anchors):
    V, F, _ = grid(bend=0.0)
    with pytest.raises(SingularStiffnessError, match=r"rotate about an axis along \[0\.0, 0\.0, 1\.0\]"):
        Physics(LipMesh(V, F, anchors=anchors))


def test_two_anchors_hold_a_flat_sheet_with_a_warning(caplog):
    V, F, idx = grid(bend=0.0)  # the thesis's Fig 2-2 fixes two corners
    ph = Physics(LipMesh(V, F, anchors=[idx[0, 0], idx[-1, -1]]))
    assert np.isfinite(ph.displace(np.ones((ph.n_nodes, 3)))).all()
    assert "all on one line" in caplog.text  # the line through them is held by eq 2.13 only
    caplog.clear()
    Vb, Fb, _ = grid()  # three anchors on a line (along y) of a curved sheet: held, with a warning
    Physics(LipMesh(Vb, Fb, anchors=idx[:3, 0]))
    assert "all on one line" in caplog.text
    caplog.clear()
    Physics(bent_mesh())  # three anchors on the parabola: no warning
    assert "one line" not in caplog.text
    caplog.clear()
    Physics(LipMesh(V, F, anchors=[idx[0, 0], idx[0, -1], idx[-1, 3]]))
    assert "one line" not in caplog.text


@pytest.mark.parametrize("solver", SOLVERS)
def test_factorisation_rejects_a_numerically_singular_matrix(solver):
    # second line of defence: a sheet hanging on faces with E ~ 1e-17 passes the graph checks
    V, F, idx = grid(nx=8, ny=4)
    E = np.where(V[F].mean(axis=1)[:, 1] < 1.0, 1e-17, 1.0)
    with pytest.raises(SingularStiffnessError, match="singular|positive definite"):
        Physics(LipMesh(V, F, anchors=idx[0, :3]), E, solver=solver)
    # and a singular matrix handed straight to the factoriser
    lap = sp.diags([-np.ones(9), 2 * np.ones(10), -np.ones(9)], [-1, 0, 1]).tolil()
    lap[0, 0] = lap[-1, -1] = 1.0  # free-free Laplacian: constant null vector
    with pytest.raises(SingularStiffnessError):
        factorize(lap.tocsc(), solver)


def test_stiffness_errors():
    mesh = bent_mesh()
    with pytest.raises(ValueError, match=r"unknown region\(s\) \['lipp'\]"):
        Physics(mesh, {"lipp": 1.0})
    with pytest.raises(ValueError, match=r"face 3 .* E = -1.0"):
        Physics(mesh, np.r_[np.ones(3), -1.0, np.ones(mesh.n_faces - 4)])
    with pytest.raises(ValueError, match=rf"shape \({mesh.n_faces},\).*got shape \(5,\)"):
        Physics(mesh, np.ones(5))
    with pytest.raises(ValueError, match="E = nan"):
        Physics(mesh, {"lip": float("nan")})
    odd = LipMesh(mesh.vertices, mesh.faces, np.zeros(mesh.n_faces, int), anchors=mesh.anchors,
                  region_names=("cheek",))
    with pytest.raises(ValueError, match=r"no stiffness for region\(s\) \['cheek'\]"):
        Physics(odd)
    with pytest.raises(ValueError, match="Poisson"):
        element_stiffness(mesh.vertices[mesh.faces], 1.0, nu=0.5)
    with pytest.raises(ValueError, match="out_of_plane"):
        Physics(mesh, out_of_plane="plate")
    with pytest.raises(ValueError, match="solver"):
        Physics(mesh, solver="dense")
    with pytest.raises(TypeError, match="LipMesh"):
        Physics(mesh.vertices)


def test_degenerate_element():
    tri = np.array([[[0, 0, 0], [1, 0, 0], [2, 0, 0]]], float)
    with pytest.raises(MeshError, match="degenerate"):
        element_stiffness(tri, 1.0)


def test_force_errors(physics):
    n = physics.n_nodes
    F = np.zeros((n, 3))
    F[5, 1] = np.nan
    with pytest.raises(ValueError, match=r"F has 1 non-finite .* shape \(30, 3\).* \(5, 1\)"):
        physics.displace(F)
    with pytest.raises(ValueError, match=r"F must have shape \(30, 3\) or \(b, 30, 3\).*got \(30, 2\)"):
        physics.displace(np.zeros((n, 2)))
    with pytest.raises(ValueError, match=r"got \(29, 3\)"):
        physics.displace(np.zeros((n - 1, 3)))
    with pytest.raises(ValueError, match=r"rhs must have shape \(90,\)"):
        physics.solve(np.zeros(89))
    with pytest.raises(ValueError, match=r"U must have shape"):
        physics.strain_energy(np.zeros(3))
    with pytest.raises(ValueError, match=r"U must have shape \(30, 3\)"):
        physics.relinearized(np.zeros((3, 3)))
    bad = np.zeros((n, 3))
    bad[0, 0] = np.inf
    with pytest.raises(ValueError, match="U has 1 non-finite"):
        physics.relinearized(bad)


def test_goal_errors(physics):
    n = physics.n_nodes
    anchor = int(physics.mesh.anchors[1])
    with pytest.raises(ValueError, match=rf"anchored nodes, e.g. DOF {3 * anchor} \(node {anchor}\)"):
        physics.reach(dofs([anchor, 20]), np.zeros(6))
    with pytest.raises(ValueError, match=r"out of range \[0, 90\)"):
        physics.reach([3 * n], [1.0])
    with pytest.raises(ValueError, match=r"repeats index\(es\) \[61\]"):
        physics.reach([61, 61], [1.0, 1.0])
    with pytest.raises(ValueError, match=r"values must have shape \(2,\) or \(b, 2\).*got \(3,\)"):
        physics.reach([60, 61], [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match=r"values has 1 non-finite .*shape \(2, 2\)"):
        physics.reach([60, 61], [[1.0, 2.0], [np.nan, 0.0]])
    with pytest.raises(ValueError, match="must not be empty"):
        physics.reach([], [])
    with pytest.raises(TypeError, match="integer"):
        physics.reach([60.5], [1.0])
    with pytest.raises(ValueError, match="anchored"):
        physics.compliance_columns([3 * anchor + 2])
    with pytest.raises(ValueError, match="one set of goals"):
        physics.to_rest_state([60], [[1.0], [2.0]])
    with pytest.raises(ValueError, match="axes must be"):
        dofs([1], "xw")
    with pytest.raises(ValueError, match="axes must be"):
        dofs([1], "xx")
    with pytest.raises(ValueError, match=r"nodes has 1 index\(es\) out of range \[0, 30\)"):
        dofs([30], n_nodes=30)


def test_collapsing_relinearisation_is_a_mesh_error(physics):
    U = -physics.mesh.vertices + physics.mesh.vertices[0]  # everything onto one point
    with pytest.raises(MeshError):
        physics.relinearized(U)
