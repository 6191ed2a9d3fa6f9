"""The thin-shell element (eqs 2.9-2.14) against closed forms and an independent FEM code."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lipgen.fem import assemble_stiffness, element_stiffness
from lipgen.mesh.lipmesh import LipMesh

NU = 0.01


def random_triangles(m, seed=0):
    rng = np.random.default_rng(seed)
    tri = rng.standard_normal((m, 3, 3)) * rng.uniform(0.5, 5.0, (m, 1, 1))
    return tri + rng.standard_normal((m, 1, 3)) * 10


def cst_zienkiewicz(xy, E, nu):
    """Plane-strain CST, Zienkiewicz & Taylor: k_ij = t/(4A) [[b_i b_j D11 + c_i c_j D33, ...]]."""
    (x1, y1), (x2, y2), (x3, y3) = xy
    b = [y2 - y3, y3 - y1, y1 - y2]
    c = [x3 - x2, x1 - x3, x2 - x1]
    A = 0.5 * ((x2 - x1) * (y3 - y1) - (x3 - x1) * (y2 - y1))
    f = E / ((1 + nu) * (1 - 2 * nu))
    D11 = D22 = f * (1 - nu)
    D12 = f * nu
    D33 = f * (1 - 2 * nu) / 2
    k = np.zeros((6, 6))
    for i in range(3):
        for j in range(3):
            k[2 * i, 2 * j] = b[i] * b[j] * D11 + c[i] * c[j] * D33
            k[2 * i, 2 * j + 1] = b[i] * c[j] * D12 + c[i] * b[j] * D33
            k[2 * i + 1, 2 * j] = c[i] * b[j] * D12 + b[i] * c[j] * D33
            k[2 * i + 1, 2 * j + 1] = c[i] * c[j] * D22 + b[i] * b[j] * D33
    return k / (4 * abs(A))


def literal_element(tri, E, nu):
    """Eqs 2.9-2.14 and 2.7 step by step: local frame, interleave, Tᵀ k T."""
    p1, p2, p3 = tri
    i_hat = (p2 - p1) / np.linalg.norm(p2 - p1)
    n = np.cross(p2 - p1, p3 - p1)
    k_hat = n / np.linalg.norm(n)
    j_hat = np.cross(k_hat, i_hat)
    lam = np.array([i_hat, j_hat, k_hat])
    xy = np.array([[0.0, 0.0], [(p2 - p1) @ i_hat, 0.0], [(p3 - p1) @ i_hat, (p3 - p1) @ j_hat]])
    kxy = cst_zienkiewicz(xy, E, nu)
    kz = E * (1 - nu) / ((1 + nu) * (1 - 2 * nu)) * np.array([[1, -.5, -.5], [-.5, 1, -.5], [-.5, -.5, 1]])
    k = np.zeros((9, 9))
    ip, op = [0, 1, 3, 4, 6, 7], [2, 5, 8]
    k[np.ix_(ip, ip)] = kxy
    k[np.ix_(op, op)] = kz
    T = np.kron(np.eye(3), lam)
    return T.T @ k @ T


def test_element_matches_literal_construction():
    tri = random_triangles(20)
    E = np.linspace(0.1, 3.0, 20)
    k = element_stiffness(tri, E, NU)
    for t, e, ke in zip(tri, E, k, strict=True):
        ref = literal_element(t, e, NU)
        assert np.allclose(ke, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())


def test_inplane_block_is_closed_form_cst():
    # A triangle in the x-y plane with edge 1->2 along +x: local frame = global frame.
    tri = np.array([[[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [1.2, 2.1, 0.0]]])
    k = element_stiffness(tri, 2.5, NU)[0]
    ip = [0, 1, 3, 4, 6, 7]
    ref = cst_zienkiewicz(tri[0, :, :2], 2.5, NU)
    assert np.allclose(k[np.ix_(ip, ip)], ref, rtol=1e-13, atol=1e-13)
    kz = 2.5 * (1 - NU) / ((1 + NU) * (1 - 2 * NU)) * np.array([[1, -.5, -.5], [-.5, 1, -.5], [-.5, -.5, 1]])
    assert np.allclose(k[np.ix_([2, 5, 8], [2, 5, 8])], kz, rtol=1e-13)
    assert np.allclose(k[np.ix_(ip, [2, 5, 8])], 0.0, atol=1e-14)


def test_symmetric_psd_with_four_zero_modes():
    k = element_stiffness(random_triangles(50, seed=3), 1.7, NU)
    assert np.abs(k - k.transpose(0, 2, 1)).max() <= 1e-13 * np.abs(k).max()
    w = np.linalg.eigvalsh(k)
    scale = w[:, -1:]
    assert (w >= -1e-12 * scale).all()
    # 3 translations + the in-plane rotation cost nothing; all else strains.
    assert (np.abs(w[:, :4]) <= 1e-12 * scale).all()
    assert (w[:, 4] > 1e-6 * scale[:, 0]).all()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rigid_motions_cost_no_energy(seed):
    rng = np.random.default_rng(seed)
    # A triangle in the x-y plane, then rotated arbitrarily in 3D and moved.
    flat = np.array([[0.0, 0.0, 0.0], [2.0, 0.3, 0.0], [0.7, 1.9, 0.0]])
    rot = Rotation.random(random_state=seed).as_matrix()
    tri = flat @ rot.T + rng.standard_normal(3)
    k = element_stiffness(tri[None], 1.0, NU)[0]
    ex, ey, ez = rot[:, 0], rot[:, 1], rot[:, 2]  # in-plane axes and normal, in 3D
    centre = tri.mean(axis=0)
    motions = {
        "in-plane x": np.tile(ex, 3),
        "in-plane y": np.tile(ey, 3),
        "out-of-plane": np.tile(ez, 3),
        "in-plane rotation": np.cross(ez, tri - centre).ravel(),
    }
    for name, u in motions.items():
        assert u @ k @ u <= 1e-12 * np.abs(k).max() * (u @ u), name
    # eq 2.13 has no rigid tilt: rotating out of the plane stretches the element
    tilt = np.cross(ex, tri - centre).ravel()
    assert tilt @ k @ tilt > 1e-3 * np.abs(k).max() * (tilt @ tilt)


def test_E_scales_the_whole_element():
    tri = random_triangles(4)
    assert np.allclose(element_stiffness(tri, 3.0), 3.0 * element_stiffness(tri, 1.0), rtol=1e-13)


def test_laplacian_option_equals_thesis_on_equilateral_triangle():
    tri = np.array([[[0, 0, 0], [2, 0, 0], [1, np.sqrt(3), 0]]], float)
    a = element_stiffness(tri, 1.0, out_of_plane="thesis")
    b = element_stiffness(tri, 1.0, out_of_plane="laplacian")
    assert np.allclose(a, b, rtol=1e-12, atol=1e-12)
    skinny = np.array([[[0, 0, 0], [4, 0, 0], [2, 0.5, 0]]], float)
    assert not np.allclose(element_stiffness(skinny, 1.0, out_of_plane="laplacian"),
                           element_stiffness(skinny, 1.0))


def test_flat_mesh_inplane_matches_scikit_fem():
    skfem = pytest.importorskip("skfem")
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    rng = np.random.default_rng(7)
    g = np.linspace(0.0, 6.0, 7)
    X, Y = np.meshgrid(g, g)
    pts = np.c_[X.ravel(), Y.ravel()]
    inner = (pts > 0).all(1) & (pts < 6).all(1)
    pts[inner] += rng.uniform(-0.3, 0.3, (inner.sum(), 2))  # irregular triangles
    sk_mesh = skfem.MeshTri.init_tensor(g, g)
    sk_mesh = skfem.MeshTri(pts[_match(sk_mesh.p.T, np.c_[X.ravel(), Y.ravel()])].T, sk_mesh.t)
    E = 1.3
    basis = skfem.Basis(sk_mesh, skfem.ElementVector(skfem.ElementTriP1()))
    K_ref = linear_elasticity(*lame_parameters(E, NU)).assemble(basis).toarray()

    faces = sk_mesh.t.T.copy()
    V = np.c_[sk_mesh.p.T, np.zeros(sk_mesh.p.shape[1])]
    mesh = LipMesh(V, faces, anchors=[0, 1])
    K = assemble_stiffness(mesh, E, NU).toarray()
    nodal = basis.nodal_dofs  # (2, n): skfem's DOF of x and y at each node
    ours = np.concatenate([3 * np.arange(mesh.n_nodes), 3 * np.arange(mesh.n_nodes) + 1])
    theirs = np.concatenate([nodal[0], nodal[1]])
    K_xy = K[np.ix_(ours, ours)]
    assert np.abs(K_xy - K_ref[np.ix_(theirs, theirs)]).max() <= 1e-10 * np.abs(K_ref).max()
    z = 3 * np.arange(mesh.n_nodes) + 2
    assert np.abs(K[np.ix_(ours, z)]).max() <= 1e-12 * np.abs(K_ref).max()  # flat: decoupled


def _match(a, b):
    """Index i with a[k] == b[i[k]] for two point sets that are permutations of each other."""
    key_b = {tuple(np.round(p, 9)): i for i, p in enumerate(b)}
    return np.array([key_b[tuple(np.round(p, 9))] for p in a])
