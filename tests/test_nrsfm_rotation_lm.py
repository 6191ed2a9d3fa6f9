"""The corrective triple's arithmetic made cheaper: against the plain formulas it replaced.

The residual and the QR's R factor below 64 columns must give the very bits of the plain code;
the trace-norm ADMM (few values kept: the subset eigensolver) agrees with the plain iteration to
1e-8; the regrouped Jacobian, the QR from 64 columns on (``dgeqrt``), the damped step (``dtpqrt``)
and the ADMM's one-product shrinkage are the same values to rounding, pinned here against the plain
formulas or an independent solver.
"""

import numpy as np
import pytest
import scipy.linalg

from lipgen.nrsfm import bmm
from lipgen.nrsfm._lm import _DampedStep, _r_factor
from lipgen.nrsfm._rotation import _Metric, _metric_terms, expm_so3


def _plain_residual(x, M1, M2):
    p, q, a, b, c = _metric_terms(x.reshape(-1, 3), M1, M2)
    scale = np.mean(a + b)
    return np.concatenate([a - b, 2 * c]) / scale


def _plain_jacobian(x, M1, M2):
    p, q, a, b, c = _metric_terms(x.reshape(-1, 3), M1, M2)
    F = M1.shape[0]
    scale = np.mean(a + b)
    da = 2 * (M1[:, :, None] * p[:, None, :]).reshape(F, -1)
    db = 2 * (M2[:, :, None] * q[:, None, :]).reshape(F, -1)
    dc = (M1[:, :, None] * q[:, None, :] + M2[:, :, None] * p[:, None, :]).reshape(F, -1)
    dscale = (da + db).mean(0)
    r1, r2 = (a - b) / scale, 2 * c / scale
    J1 = (da - db) / scale - np.outer(r1, dscale) / scale
    J2 = 2 * dc / scale - np.outer(r2, dscale) / scale
    return np.vstack([J1, J2])


@pytest.mark.parametrize(("F", "r"), [(300, 36), (40, 6), (3, 3)])
def test_metric_gives_the_plain_formulas(F, r):
    rng = np.random.default_rng(F + r)
    M = rng.standard_normal((2 * F, r)) * np.logspace(-3, 3, r)
    M1, M2 = M[0::2], M[1::2]
    metric = _Metric(M1, M2)
    for _ in range(3):
        x = rng.standard_normal(3 * r)
        # the residual first (its terms are reused by the Jacobian at the same x), then the other order
        assert np.array_equal(metric.residual(x), _plain_residual(x, M1, M2))
        _assert_rounding(metric.jacobian(x), x, M1, M2)
        y = x + 1e-9
        _assert_rounding(metric.jacobian(y), y, M1, M2)
        assert np.array_equal(metric.residual(y), _plain_residual(y, M1, M2))


def _assert_rounding(J, x, M1, M2):
    """J equals the plain Jacobian to within a few ulps of its terms' magnitudes (the regrouping
    cancels differently where the terms cancel)."""
    p, q, a, b, c = _metric_terms(x.reshape(-1, 3), M1, M2)
    F = M1.shape[0]
    scale = np.mean(a + b)
    da = np.abs(2 * (M1[:, :, None] * p[:, None, :]).reshape(F, -1))
    db = np.abs(2 * (M2[:, :, None] * q[:, None, :]).reshape(F, -1))
    dc = (np.abs(2 * (M1[:, :, None] * q[:, None, :]).reshape(F, -1))
          + np.abs(2 * (M2[:, :, None] * p[:, None, :]).reshape(F, -1)))
    dscale = (da + db).mean(0)
    r1, r2 = np.abs(a - b) / scale, np.abs(2 * c) / scale
    size = np.vstack([(da + db) / scale + np.outer(r1, dscale) / scale,
                      dc / scale + np.outer(r2, dscale) / scale])
    plain = _plain_jacobian(x, M1, M2)
    assert np.all(np.abs(J - plain) <= 64 * np.finfo(float).eps * size)
    assert not np.array_equal(size, 0 * size)


@pytest.mark.parametrize(("m", "n"), [(600, 45), (160, 9), (20, 27), (2204, 3)])
def test_r_factor_gives_scipy_qr_bits(m, n):
    rng = np.random.default_rng(m * n)
    J, r = rng.standard_normal((m, n)), rng.standard_normal(m)
    expected = scipy.linalg.qr(np.column_stack([J, r]), mode="r", check_finite=False)[0]
    got = _r_factor(J, r)
    assert got.shape == (min(m, n + 1), n + 1)
    assert np.array_equal(got, expected[: n + 1])


@pytest.mark.parametrize(("m", "n"), [(2204, 117), (480, 63), (40, 80)])
def test_r_factor_from_64_columns_gives_scipy_qr_to_rounding(m, n):
    # dgeqrt: the same Householder reflections as dgeqrf, blocked otherwise (so the same signs)
    rng = np.random.default_rng(m + n)
    J = rng.standard_normal((m, n)) * np.logspace(-2, 2, n)
    r = rng.standard_normal(m)
    expected = scipy.linalg.qr(np.column_stack([J, r]), mode="r", check_finite=False)[0][: n + 1]
    got = _r_factor(J, r)
    assert got.shape == expected.shape == (min(m, n + 1), n + 1)
    assert np.array_equal(got, np.triu(got))
    column = np.linalg.norm(np.column_stack([J, r]), axis=0)
    assert np.all(np.abs(got - expected) <= 1e-13 * column)


def test_damped_step_solves_the_stacked_least_squares_problem():
    rng = np.random.default_rng(5)
    n = 12
    Rj = np.triu(rng.standard_normal((n, n)))
    Rj[:, -2:] = Rj[:, :2] @ rng.standard_normal((2, 2))  # rank deficient, as the gauge makes it
    qtr = rng.standard_normal(n)
    root = np.exp(rng.standard_normal(n))
    step = _DampedStep(Rj, qtr, root)
    rhs = np.concatenate([-qtr, np.zeros(n)])
    for lam in (1e-15, 1e-6, 1e-3, 1.0, 1e6):
        stacked = np.vstack([Rj, np.diag(np.sqrt(lam) * root)])
        expected = np.linalg.lstsq(stacked, rhs, rcond=None)[0]
        np.testing.assert_allclose(step(lam), expected, rtol=1e-7, atol=1e-9 * np.abs(expected).max())
    # lam 0: the minimum-norm least-squares step, by the same call as before
    expected = np.linalg.lstsq(np.vstack([Rj, np.zeros((n, n))]), rhs, rcond=None)[0]
    assert np.array_equal(step(0.0), expected)


def test_damped_step_of_a_wide_factor_and_a_dead_parameter():
    # R of [J | r] has fewer rows than columns when J does; a zero column (a parameter with no effect,
    # scale 1) leaves the other coordinates' step that of the system without it
    rng = np.random.default_rng(8)
    n, rows = 9, 6
    Rj = np.triu(rng.standard_normal((rows, n)))
    qtr, root = rng.standard_normal(rows), np.exp(rng.standard_normal(n))
    for lam in (1e-12, 1e-3, 10.0):
        stacked = np.vstack([Rj, np.diag(np.sqrt(lam) * root)])
        expected = np.linalg.lstsq(stacked, np.concatenate([-qtr, np.zeros(n)]), rcond=None)[0]
        np.testing.assert_allclose(_DampedStep(Rj, qtr, root)(lam), expected, rtol=1e-10, atol=1e-12)
    Rd = np.triu(rng.standard_normal((n, n)))
    Rd[:, 3] = 0.0
    live = [i for i in range(n) if i != 3]
    root[3] = 1.0
    qtr = rng.standard_normal(n)
    for lam in (1e-15, 1e-3, 10.0):
        full = _DampedStep(Rd, qtr, root)(lam)
        reduced = np.linalg.lstsq(np.vstack([Rd[:, live], np.diag(np.sqrt(lam) * root[live])]),
                                  np.concatenate([-qtr, np.zeros(n - 1)]), rcond=None)[0]
        assert full[3] == 0.0
        np.testing.assert_allclose(full[live], reduced, rtol=1e-9, atol=1e-12 * np.abs(reduced).max())


def test_a_parameter_without_effect_stays_put():
    # review finding: with its scale at ~0 the SVD's round-off in that coordinate grew to ~1e146
    from lipgen.nrsfm._lm import levenberg_marquardt

    rng = np.random.default_rng(0)
    A = rng.standard_normal((20, 6))
    A[:, 2] = 0.0
    b = 0.5 * rng.standard_normal(20)
    x, cost, _ = levenberg_marquardt(lambda x: np.tanh(A @ x) - b,
                                     lambda x: (1 - np.tanh(A @ x) ** 2)[:, None] * A, np.zeros(6))
    assert x[2] == 0.0
    live = [0, 1, 3, 4, 5]

    def fun5(y):
        return np.tanh(A[:, live] @ y) - b

    def jac5(y):
        return (1 - np.tanh(A[:, live] @ y) ** 2)[:, None] * A[:, live]

    x5, cost5, _ = levenberg_marquardt(fun5, jac5, np.zeros(5))
    assert cost == pytest.approx(cost5, rel=1e-12)
    # both stop within their ftol of one minimiser, found here to full precision by Gauss-Newton steps
    # (the two runs round differently, and the cost is flat there: each is ~1e-9 from it)
    best = x5.copy()
    for _ in range(5):
        best -= np.linalg.lstsq(jac5(best), fun5(best), rcond=None)[0]
    np.testing.assert_allclose(x[live], best, rtol=0, atol=1e-8)
    np.testing.assert_allclose(x5, best, rtol=0, atol=1e-8)


def _plain_trace_norm_shapes(Wc, R, mask=None, tol=1e-8, max_iter=1000, growth=1.1):
    F, P = R.shape[0], Wc.shape[1]
    seen3 = (np.ones((F, P), dtype=bool) if mask is None else mask)[:, None, :]
    base = np.einsum("fji,fjp->fip", R[:, :2], Wc.reshape(F, 2, P)) * seen3
    depth_axis = R[:, 2][:, :, None]
    A, Y = base.copy(), np.zeros_like(base)
    rho = 1.0 / max(np.linalg.norm(base.reshape(F, -1), 2), 1e-300)
    norm0 = np.linalg.norm(base)
    for _ in range(max_iter):
        Z = (A - Y / rho).reshape(F, -1)
        w, V = np.linalg.eigh(Z.T @ Z)
        s = np.sqrt(np.maximum(w, 0.0))
        keep = s > 1.0 / rho
        X = (
            (Z @ V[:, keep]) * (1.0 - (1.0 / rho) / s[keep]) @ V[:, keep].T
            if keep.any()
            else np.zeros_like(Z)
        ).reshape(F, 3, P)
        T = X + Y / rho
        depth = np.einsum("fik,fip->fkp", depth_axis, T)
        A = np.where(seen3, base + depth_axis * depth, T)
        gap = np.linalg.norm(X - A)
        Y += rho * (X - A)
        if gap <= tol * max(np.linalg.norm(A), norm0):
            break
        rho *= growth
    return A


@pytest.mark.parametrize("hidden", [False, True])
def test_trace_norm_shapes_give_the_plain_iterations(hidden):
    rng = np.random.default_rng(11)
    F, P, K = 40, 9, 2
    basis = rng.standard_normal((K, 3, P))
    shapes = np.einsum("fk,kip->fip", rng.standard_normal((F, K)), basis)
    R = np.stack([expm_so3(0.05 * f * np.array([0.3, 1.0, 0.1])) for f in range(F)])
    W = np.einsum("fij,fjp->fip", R[:, :2], shapes).reshape(2 * F, P)
    Wc = W - W.mean(axis=1, keepdims=True)
    mask = rng.random((F, P)) > 0.15 if hidden else None
    expected = _plain_trace_norm_shapes(Wc, R, mask)
    got = bmm.min_trace_norm_shapes(Wc, R, mask)
    # few values kept here: the eigenpairs above the threshold only (dsyevr). Exactly K shapes make
    # the iteration ill-conditioned (the plain one moves by 6-8e-10 when Wc moves by 1e-15 of
    # itself), so the same to within the ADMM's stopping tolerance (1e-8 of the shapes' norm)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-8 * np.abs(expected).max())
    if hidden:  # a 0/1 mask means the same; a mask of another shape is named
        assert np.array_equal(bmm.min_trace_norm_shapes(Wc, R, mask.astype(int)), got)
        with pytest.raises(ValueError, match=r"mask must be \(F, P\) = \(40, 9\).*\(40, 8\)"):
            bmm.min_trace_norm_shapes(Wc, R, mask[:, :8])


@pytest.mark.parametrize("tau_rank", [2, 20, 29])
def test_shrink_gives_the_thresholded_svd(tau_rank):
    # both of the shrinkage's products (few values kept, most kept) against U max(s - tau, 0) V^T
    rng = np.random.default_rng(tau_rank)
    Z = rng.standard_normal((50, 30)) @ np.diag(np.logspace(0, -2, 30)) @ np.linalg.qr(
        rng.standard_normal((30, 30)))[0]
    U, s, Vt = np.linalg.svd(Z, full_matrices=False)
    tau = 0.5 * (s[tau_rank - 1] + s[tau_rank])
    expected = (U * np.maximum(s - tau, 0.0)) @ Vt
    for few in (False, True):  # all eigenpairs, or those above tau^2 only
        out = np.empty_like(Z)
        assert bmm._shrink(Z, tau, out, few=few) == tau_rank
        np.testing.assert_allclose(out, expected, rtol=0, atol=1e-12)
    out = np.empty_like(Z)
    assert bmm._shrink(Z, 2 * s[0], out, few=True) == 0 and not out.any()
    assert bmm._shrink(Z, 1e200, out, few=True) == 0 and not out.any()  # tau^2 overflows: all pairs


def test_trace_norm_shapes_keeping_most_values_give_the_plain_iterations():
    # noisy shapes: the kept rank climbs past the one-product switch (k > F n / (2F - n), here 18
    # of 30); the same iterates to rounding (2e-13 of the shapes), so the same stop
    rng = np.random.default_rng(12)
    F, P = 40, 10
    shapes = rng.standard_normal((1, 3, P)) + 0.3 * rng.standard_normal((F, 3, P))
    R = np.stack([expm_so3(0.07 * f * np.array([0.2, 1.0, 0.3])) for f in range(F)])
    W = np.einsum("fij,fjp->fip", R[:, :2], shapes).reshape(2 * F, P)
    Wc = W - W.mean(axis=1, keepdims=True)
    ranks = []
    shrink = bmm._shrink

    def counted(Z, tau, out, few):
        ranks.append(shrink(Z, tau, out, few))
        return ranks[-1]

    bmm._shrink = counted
    try:
        got = bmm.min_trace_norm_shapes(Wc, R)
    finally:
        bmm._shrink = shrink
    assert max(ranks) > 18
    expected = _plain_trace_norm_shapes(Wc, R)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9 * np.abs(expected).max())


@pytest.mark.parametrize("few", [False, True])
def test_non_finite_input_raises_instead_of_a_silent_answer(few):
    """The subset eigensolver returns no eigenpairs for a NaN Gram matrix (a silent zero), and a NaN
    Jacobian made every damping trial fail quietly: both now raise."""
    from lipgen.nrsfm import bmm
    from lipgen.nrsfm._lm import _DampedStep

    Z = np.ones((6, 4))
    Z[2, 1] = np.nan
    with pytest.raises(np.linalg.LinAlgError, match="NaN or inf"):
        bmm._shrink(Z, 0.5, np.empty_like(Z), few=few)
    Rj = np.triu(np.ones((3, 3)))
    Rj[0, 2] = np.inf
    with pytest.raises(FloatingPointError, match="NaN or inf"):
        _DampedStep(Rj, np.ones(3), np.ones(3))
