"""The tissue layer's stiffness: the stress derivative against finite differences of the stress,
its positive semi-definite part, and the assembled tangent against finite differences of the
layer's own gradient (with the contact springs engaged)."""

import numpy as np
import pytest

from lipgen.mesh.procedural import lip_mesh
from lipgen.subject.layer_build import build_layer
from lipgen.subject.layer_stiffness import stress_derivative


def _stress(F, mu, lam, kappa):
    """First Piola-Kirchhoff stress, written independently of the library: the derivative of
    ``mu |E|^2 + lam/2 tr(E)^2 + kappa/2 (det F - 1)^2`` is ``F S + kappa (J - 1) J F^-T``."""
    E = 0.5 * (np.swapaxes(F, -1, -2) @ F - np.eye(3))
    S = 2 * mu[:, None, None] * E + (lam * np.trace(E, axis1=1, axis2=2))[:, None, None] * np.eye(3)
    J = np.linalg.det(F)
    return F @ S + (kappa * (J - 1) * J)[:, None, None] * np.swapaxes(np.linalg.inv(F), 1, 2)


def _deformations(n, scale, seed=0):
    rng = np.random.default_rng(seed)
    mu, lam, kappa = rng.uniform(0.5, 2, n), rng.uniform(0, 3, n), rng.uniform(1, 40, n)
    return np.eye(3) + scale * rng.normal(size=(n, 3, 3)), mu, lam, kappa


def test_the_stress_derivative_is_the_derivative_of_the_stress():
    F, mu, lam, kappa = _deformations(30, 0.3)
    C = stress_derivative(F, mu, lam, kappa)
    h = 1e-6
    for q in range(9):
        d = np.zeros(9)
        d[q] = h
        d = d.reshape(3, 3)
        fd = (_stress(F + d, mu, lam, kappa) - _stress(F - d, mu, lam, kappa)) / (2 * h)
        assert np.allclose(C[:, :, q], fd.reshape(-1, 9), rtol=1e-6, atol=1e-6 * np.abs(C).max())


def test_the_psd_part_is_positive_semidefinite_and_exact_without_stress():
    F, mu, lam, kappa = _deformations(200, 0.4, seed=1)
    exact = np.linalg.eigvalsh(stress_derivative(F, mu, lam, kappa))
    part = np.linalg.eigvalsh(stress_derivative(F, mu, lam, kappa, psd=True))
    assert (exact.min(axis=1) < -1e-3).mean() > 0.5  # the exact one is often indefinite here
    assert part.min() > -1e-10 * np.abs(part).max()
    # a rotation strains nothing and keeps the volume: nothing is left out
    from scipy.spatial.transform import Rotation

    R = Rotation.random(20, random_state=2).as_matrix()
    m = np.ones(20)
    part, exact = (stress_derivative(R, m, 2 * m, 10 * m, psd=psd) for psd in (True, False))
    assert np.allclose(part, exact, atol=1e-12)


@pytest.fixture(scope="module")
def touching():
    """A layer with contact pairs, deformed so that part of the lips press on each other."""
    from lipgen.subject.motion import _contact_pairs

    m = lip_mesh(0)
    pairs = _contact_pairs(m)
    L = build_layer(m, np.linspace(0.5, 2, m.n_faces), np.full(m.n_nodes, 1.2), contact_pairs=pairs,
                    contact_stiffness=80.0, gum_nodes=np.linspace(0, 1, m.n_nodes))
    rng = np.random.default_rng(3)
    x = L.rest + 0.15 * rng.normal(size=L.rest.shape)
    x[pairs[::2, 0], 1] = L.rest[pairs[::2, 1], 1] - 0.3  # every other pair crossed by 0.3 mm
    return L, x, pairs


def test_the_tangent_is_the_derivative_of_the_gradient(touching):
    L, x, pairs = touching
    assert 0 < (x[pairs[:, 0], 1] < x[pairs[:, 1], 1]).sum() < len(pairs)
    M = L.tangent(x, psd=False).toarray()
    f = np.zeros_like(x)
    h = 1e-6
    engaged = 3 * pairs[::2, 0] + 1  # the engaged contact springs' y dofs
    for d in np.concatenate([np.random.default_rng(4).choice(x.size, 25, replace=False), engaged]):
        xp, xm = x.copy(), x.copy()
        xp.flat[d] += h
        xm.flat[d] -= h
        fd = (L.energy_grad(xp, f)[1] - L.energy_grad(xm, f)[1]).ravel() / (2 * h)
        assert np.allclose(M[:, d], fd, rtol=1e-5, atol=1e-6 * np.abs(M[:, d]).max())


def test_the_solvers_matrix_is_the_free_block_and_positive_definite(touching):
    L, x, _ = touching
    dof = np.repeat(~L.fixed, 3)
    full = L.tangent(x)
    free = L.tangent(x, free_only=True)
    assert abs(free - full[dof][:, dof]).max() <= 1e-12 * abs(full).max()
    assert np.linalg.eigvalsh(free.toarray()).min() > 0  # the springs and anchors pin it
    exact = np.linalg.eigvalsh(L.tangent(x, psd=False).toarray()[np.ix_(dof, dof)])
    assert exact.min() < 0  # at this crossed, jittered state the exact Hessian is indefinite


def test_the_positive_part_matches_an_eigendecomposition():
    from scipy.spatial.transform import Rotation

    from lipgen.subject.layer_stiffness import positive_part, symmetric_eigenvalues

    rng = np.random.default_rng(7)
    A = rng.normal(size=(500, 3, 3))
    A = A + np.swapaxes(A, 1, 2)
    # the cases a cubic's closed form finds hard: repeated eigenvalues, zeros, one sign, tiny ones
    spectra = [(0, 0, 0), (2, 2, 2), (-2, -2, -2), (1, 1, -1), (1, -1, -1), (3, 0, 0), (0, 0, -3), (1, 0, -1),
               (1e-9, -1, -1), (1, 1, -1e-9), (5, 5, 5 + 1e-7), (1e6, 1, -1)]
    R = Rotation.random(len(spectra), random_state=8).as_matrix()
    special = np.einsum("tij,tj,tkj->tik", R, np.array(spectra, float), R)
    for S in (A, special):
        w, U = np.linalg.eigh(S)
        ref = (U * np.maximum(w, 0.0)[:, None, :]) @ np.swapaxes(U, 1, 2)
        scale = np.abs(w).max(axis=1)[:, None, None] + 1e-300
        assert np.all(np.abs(positive_part(S) - ref) <= 1e-7 * scale)
        lam = symmetric_eigenvalues(S)
        assert np.all(np.abs(lam - w[:, ::-1]) <= 1e-7 * scale[:, :, 0])
    assert np.array_equal(positive_part(special[:1]), np.zeros((1, 3, 3)))


@pytest.mark.parametrize("method", ["cholmod", "superlu"])
def test_a_pattern_factorisation_solves_each_matrix_of_the_pattern(touching, method):
    from lipgen.fem.solver import cholmod_available
    from lipgen.subject.layer_stiffness import PatternCholesky, spd_solver

    if method == "cholmod" and not cholmod_available():
        pytest.skip("cvxopt is not installed: pip install 'lipgen[fast]'")
    L, x, _ = touching
    A = L.tangent(x, free_only=True)
    chol = PatternCholesky(A, method)
    assert chol.method == method
    B = L.tangent(L.rest + 0.5 * (x - L.rest), free_only=True)   # another matrix of the same pattern
    b = np.random.default_rng(9).normal(size=A.shape[0])
    for M in (A, B):
        got = chol.factor(M)(b)
        assert np.allclose(got, spd_solver(M)(b), rtol=0, atol=1e-9 * np.abs(got).max())
        assert np.abs(M @ got - b).max() <= 1e-9 * np.abs(b).max()
    dof = np.repeat(~L.fixed, 3)
    exact = L.tangent(x, psd=False)[dof][:, dof]   # indefinite here (the test above): refused, not solved
    with pytest.raises(np.linalg.LinAlgError, match="not positive definite"):
        chol.factor(exact)
    with pytest.raises(ValueError, match="pattern"):
        chol.factor(A[:-3, :-3])
    with pytest.raises(ValueError, match="method must be one of"):
        PatternCholesky(A, "lu")
