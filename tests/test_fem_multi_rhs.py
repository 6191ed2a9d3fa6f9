"""Many right-hand sides in one call: CHOLMOD's block solve and cholespy against the column loop."""

import numpy as np
import pytest
import scipy.sparse as sp

import lipgen
from lipgen.errors import SingularStiffnessError
from lipgen.fem import Physics, cholmod_available
from lipgen.fem.solver import cholespy_available, factorize

needs_cholmod = pytest.mark.skipif(not cholmod_available(), reason="cvxopt (CHOLMOD) is not installed")
needs_cholespy = pytest.mark.skipif(not cholespy_available(), reason="cholespy is not installed")


@pytest.fixture(scope="module")
def system():
    physics = Physics(lipgen.lip_mesh(1), solver="superlu")
    A = physics.K_s.tocsc()
    X = np.random.default_rng(3).standard_normal((A.shape[0], 48))
    return physics, A, X, np.asarray(A @ X)


@needs_cholmod
def test_cholmod_block_solve_equals_the_column_loop_and_the_truth(system):
    _, A, X, B = system
    fac = factorize(A, "cholmod")
    assert fac.multi_column  # the check turned the one-call path on
    block = fac._solve_block(B)
    loop = fac._solve_columns(B)
    assert block.shape == loop.shape == B.shape
    assert np.abs(block - loop).max() <= 1e-12 * np.abs(loop).max()  # round-off of the same factor
    assert np.abs(fac.solve(B) - X).max() <= 1e-8 * np.abs(X).max()  # the known solution
    assert np.linalg.norm(A @ fac.solve(B) - B) <= 1e-12 * np.linalg.norm(B)
    # one column and a (N, 1) block still go through, with their shapes
    assert fac.solve(B[:, 0]).shape == (A.shape[0],)
    assert np.allclose(fac.solve(B[:, :1])[:, 0], fac.solve(B[:, 0]), rtol=0, atol=1e-12 * np.abs(X).max())


@needs_cholmod
def test_block_solve_that_disagrees_is_not_used(system, monkeypatch, caplog):
    _, A, X, B = system
    import lipgen.fem._cholmod_dense as cd

    monkeypatch.setattr(cd, "dense_solve", lambda factor, rhs: 2.0 * np.asarray(rhs))  # wrong on purpose
    fac = factorize(A, "cholmod")
    assert not fac.multi_column and "disagrees" in caplog.text
    assert np.abs(fac.solve(B) - X).max() <= 1e-8 * np.abs(X).max()  # the loop answers


@needs_cholmod
def test_dense_solve_refuses_what_is_not_a_cholmod_factor():
    from lipgen.fem._cholmod_dense import dense_solve

    assert dense_solve(object(), np.ones((4, 2))) is None


@needs_cholespy
def test_cholespy_matches_superlu_and_rejects_indefinite(system):
    physics, A, X, B = system
    fac = factorize(A, "cholespy")
    ref = physics._factor.solve(B)
    assert np.abs(fac.solve(B) - ref).max() <= 1e-10 * np.abs(ref).max()
    assert np.abs(fac.solve(B[:, 3]) - ref[:, 3]).max() <= 1e-10 * np.abs(ref).max()
    indefinite = sp.csc_matrix(np.array([[1.0, 2.0], [2.0, 1.0]]))
    with pytest.raises(SingularStiffnessError, match="not positive definite"):
        factorize(indefinite, "cholespy")


@pytest.mark.parametrize("solver", [pytest.param("cholmod", marks=needs_cholmod),
                                    pytest.param("cholespy", marks=needs_cholespy)])
def test_reach_plan_with_block_solves_equals_the_superlu_plan(system, solver):
    reference, *_ = system
    physics = Physics(reference.mesh, solver=solver)
    d = lipgen.dofs(physics.mesh.markers, "xyz")
    goals = np.random.default_rng(4).standard_normal((3, len(d)))
    for objective in ("force", "energy"):
        U, F = physics.reach(d, goals, objective)
        U0, F0 = reference.reach(d, goals, objective)
        assert np.abs(U[:, :, :].reshape(3, -1)[:, d] - goals).max() <= 1e-9 * np.abs(goals).max()
        assert np.abs(U - U0).max() <= 1e-8 * np.abs(U0).max()
        assert np.abs(F - F0).max() <= 1e-8 * np.abs(F0).max()


def test_cholesky_qr2_is_a_thin_qr_and_declines_ill_conditioned_input():
    from lipgen.fem.reach import cholesky_qr2 as _cholesky_qr2

    rng = np.random.default_rng(5)
    # columns scaled over 4 decades, like compliance columns of near and far goal nodes
    S = np.asfortranarray(rng.standard_normal((3000, 20)) * np.logspace(0, 4, 20))
    Q, R = _cholesky_qr2(S)
    assert np.abs(Q.T @ Q - np.eye(20)).max() <= 1e-13
    assert np.abs(Q @ R - S).max() <= 1e-13 * np.abs(S).max()
    assert np.array_equal(R, np.triu(R))
    Qh, Rh = np.linalg.qr(S)  # Householder: the same factorisation up to column signs
    signs = np.sign(np.diag(Rh)) * np.sign(np.diag(R))
    assert np.allclose(R * signs[:, None], Rh, rtol=1e-10, atol=1e-10 * np.abs(Rh).max())
    S[:, 1] = S[:, 0] * (1 + 1e-9)  # cond ~1e9: CholeskyQR would lose orthogonality
    assert _cholesky_qr2(S) is None


def test_reach_plan_without_cholesky_qr_is_the_same(system, monkeypatch):
    physics, *_ = system
    d = lipgen.dofs(physics.mesh.markers, "xyz")
    goals = np.random.default_rng(6).standard_normal((2, len(d)))
    physics._plans.clear()
    U, F = physics.reach(d, goals)
    import lipgen.fem.reach as phys

    monkeypatch.setattr(phys, "cholesky_qr2", lambda S: None)  # force the Householder path
    physics._plans.clear()
    U1, F1 = physics.reach(d, goals)
    physics._plans.clear()
    assert np.abs(U - U1).max() <= 1e-9 * np.abs(U1).max()
    assert np.abs(F - F1).max() <= 1e-9 * np.abs(F1).max()


@pytest.mark.slow(cover="tests/test_fem_multi_rhs.py::test_reach_plan_with_block_solves_equals_the_superlu_plan")
@needs_cholmod
def test_solvers_bench_quick_reports_ratios():
    from lipgen.bench import available_suites, solvers

    assert "solvers" in available_suites()
    out = solvers.run(quick=True)
    assert out["resolution"] == 2 and out["right_hand_sides"] == 48 and out["multi_column"]
    ratios = [out["reach_plan_over_factor"], out["block_48_over_factor"],
              *out["over_column_loop_48"].values(), *out["over_column_loop_48_cpu"].values()]
    assert all(np.isfinite(r) and r > 0 for r in ratios)
    assert {"lipgen_48", "superlu_48"} <= set(out["over_column_loop_48"])
