"""Low-rank completion of tracks (lipgen.nrsfm.completion): the Gauss-Newton model against finite
differences, exact recovery of low-rank tracks, the time prior and its measured error."""

import numpy as np
import pytest

from lipgen.nrsfm.completion import (
    _bases,
    _Frames,
    complete_subspace,
    interpolate_in_time,
    prior_variance,
)


def _low_rank(F=60, P=14, r=6, seed=0):
    rng = np.random.default_rng(seed)
    # smooth coefficients in time, so that the time prior is informative but not exact
    t = np.linspace(0, 1, F)[:, None]
    M = np.sin(2 * np.pi * t * rng.uniform(0.5, 2.0, (1, 2 * r)) + rng.uniform(0, 6, (1, 2 * r)))
    M = M.reshape(F, 2, r).reshape(2 * F, r)
    B = rng.standard_normal((r, P))
    return M @ B + rng.standard_normal((2 * F, 1))


def _mask(F, P, frac, seed):
    rng = np.random.default_rng(seed)
    mask = rng.random((F, P)) > frac
    mask[:, 0] = True
    return mask


def test_gauss_newton_model_matches_finite_differences():
    F, P, r = 40, 12, 5
    W = _low_rank(F, P, r) + 0.05 * np.random.default_rng(1).standard_normal((2 * F, P))
    mask = _mask(F, P, 0.12, 2)
    W0 = np.where(np.repeat(mask, 2, axis=0), W, 0.0)
    d = P - 1 - r
    rng = np.random.default_rng(3)
    N, Y = _bases(rng.standard_normal((P, d)))
    frames = _Frames(W0, mask, d)
    cost, JtJ, g = frames.evaluate(N, Y)
    # cost against the direct least-squares fit of every row in span(1, Y)
    U = np.column_stack([np.ones(P), Y])
    direct = 0.0
    for f in range(F):
        o = mask[f]
        for row in (2 * f, 2 * f + 1):
            coef = np.linalg.lstsq(U[o], W[row, o], rcond=None)[0]
            direct += 0.5 * float(((W[row, o] - U[o] @ coef) ** 2).sum())
    assert cost == pytest.approx(direct, rel=1e-9)

    # gradient and Gauss-Newton matrix against central differences of the residual map
    def residuals(X):
        Nn = np.linalg.qr(N + Y @ X.reshape(r, d))[0]
        out = []
        for idx, rows in frames.groups:
            a = rows @ Nn
            if idx.shape[1]:
                NH = Nn[idx]
                Pi = np.eye(d) - NH.transpose(0, 2, 1) @ np.linalg.inv(NH @ NH.transpose(0, 2, 1)) @ NH
                a = np.einsum("nij,nkj->nki", Pi, a)
            out.append(a.ravel())
        return np.concatenate(out)

    # the residual vectors depend on the basis N chosen within span(N) only by a rotation, which QR of
    # N + Y dX fixes to first order; compare J^T r and J^T J built from a finite-difference J
    h = 1e-6
    J = np.stack([(residuals(h * e) - residuals(-h * e)) / (2 * h) for e in np.eye(r * d)], axis=1)
    res = residuals(np.zeros(r * d))
    assert 0.5 * float(res @ res) == pytest.approx(cost, rel=1e-9)
    assert np.allclose(J.T @ res, g, rtol=1e-5, atol=1e-7 * np.abs(g).max())
    assert np.allclose(J.T @ J, JtJ, rtol=1e-5, atol=1e-6 * np.abs(JtJ).max())


@pytest.mark.parametrize("frac", [0.1, 0.3])
def test_exact_low_rank_tracks_are_recovered(frac):
    F, P, r = 80, 16, 6
    W = _low_rank(F, P, r, seed=4)
    mask = _mask(F, P, frac, 5)
    Wn = np.where(np.repeat(mask, 2, axis=0), W, np.nan)
    full, misfit, info = complete_subspace(Wn, mask, r)
    assert misfit < 1e-10
    assert np.abs(full - W).max() < 1e-6 * np.abs(W).max()
    seen = np.repeat(mask, 2, axis=0)
    assert np.array_equal(full[seen], W[seen])     # observed entries untouched


def test_long_gaps_are_filled_by_the_model_not_the_time_prior():
    F, P, r = 120, 20, 4
    W = _low_rank(F, P, r, seed=6)
    mask = np.ones((F, P), dtype=bool)
    for p, start in zip(range(1, 8), (5, 20, 40, 60, 70, 85, 90), strict=True):
        mask[start:start + 25, p] = False
    full, misfit, _ = complete_subspace(W, mask, r)
    hidden = ~np.repeat(mask, 2, axis=0)
    prior_error = np.abs(interpolate_in_time(np.where(hidden, 0.0, W), mask) - W)[hidden].max()
    assert prior_error > 0.05 * np.abs(W).max()       # the prior alone is far off on these gaps
    assert np.abs(full - W)[hidden].max() < 1e-6 * np.abs(W).max()


def test_time_prior_and_its_measured_error():
    F, P = 50, 5
    frames = np.arange(F, dtype=float)
    W = np.zeros((2 * F, P))
    W[0::2] = frames[:, None] * np.arange(1, P + 1)        # linear in time: interpolation is exact
    W[1::2] = 3.0 - 0.5 * frames[:, None]
    mask = np.ones((F, P), dtype=bool)
    mask[10:13, 2] = False
    mask[30, 4] = False
    filled = interpolate_in_time(np.where(np.repeat(mask, 2, axis=0), W, -99.0), mask)
    assert np.allclose(filled, W)
    assert np.allclose(prior_variance(W, mask), 0.0)
    # a quadratic track: the midpoint rule errs by m^2 / 2 on its u coordinate, nothing elsewhere;
    # the variance per coordinate is the mean over the (frame, point) pairs seen at f - m, f, f + m
    W[0::2, 2] = 0.5 * frames**2
    var = prior_variance(W, mask)[0::2]
    for f, m in ((10, 1), (11, 2)):
        ok = [(g, p) for g in range(m, F - m) for p in range(P)
              if mask[g - m, p] and mask[g, p] and mask[g + m, p]]
        quad = sum(1 for g, p in ok if p == 2)
        assert var[f, 2] == pytest.approx(quad * (m**2 / 2) ** 2 / len(ok) / 2, rel=1e-12)


@pytest.mark.parametrize("scale", [1e-200, 1e200])
def test_any_magnitude_completes_alike(scale):
    F, P, r = 50, 12, 4
    W = _low_rank(F, P, r, seed=7)
    mask = _mask(F, P, 0.15, 8)
    full, misfit, info = complete_subspace(W * scale, mask, r)
    assert misfit < 1e-10 and np.isfinite(full).all()
    assert np.abs(full / scale - W).max() < 1e-6 * np.abs(W).max()


def test_hide_points_hides_the_fraction_asked_at_random_or_in_runs():
    from lipgen.experiments.nrsfm_benchmarks import hide_points

    random = hide_points(500, 40, "random", 0.1, seed=1)
    assert random.shape == (500, 40) and abs((~random).mean() - 0.1) < 0.01
    gaps = hide_points(500, 40, "gaps", 0.1, seed=1)
    assert 0.1 <= (~gaps).mean() < 0.1 + 60 / (500 * 40)
    # hidden in runs: a hidden entry's neighbour in time is mostly hidden too
    def run_share(hidden):
        return (hidden[1:] & hidden[:-1]).sum() / hidden.sum()

    assert run_share(~gaps) > 0.9 and run_share(~random) < 0.2
    assert np.array_equal(gaps, hide_points(500, 40, "gaps", 0.1, seed=1))


def _fill_by_constraint(W0, prior, mask, N):
    """Each frame's hidden entries with the model exact: min sum D (x - prior)^2 subject to the
    model's rows (N_H^T x = -N^T w~), by its closed form (Lagrange multipliers), frame by frame."""
    F, P = mask.shape
    out = W0.reshape(F, 2, P).copy()
    var = prior_variance(W0, mask)[::2]
    for f in np.flatnonzero((~mask).any(1)):
        idx = np.flatnonzero(~mask[f])
        NH, Dinv = N[idx], var[f, idx]
        for c in range(2):
            s, k = prior.reshape(F, 2, P)[f, c, idx], out[f, c] @ N
            lam = np.linalg.solve((NH.T * Dinv) @ NH, NH.T @ s + k)
            out[f, c, idx] = s - Dinv * (NH @ lam)
    return out.reshape(2 * F, P)


def test_an_exact_model_with_fewer_rows_than_hidden_entries_is_filled_not_singular():
    """Rank P - 2 leaves one model row per frame; with its noise at the floor the normal equations'
    matrix rounded to a singular one (LinAlgError on drink with 10 % hidden at K = 13). The stacked
    least squares gives the exact-model closed form, and the moderate-noise answer is unchanged."""
    from lipgen.nrsfm.time_prior import fill_hidden as _fill

    F, P = 40, 10
    W = _low_rank(F, P, P - 2, seed=8)
    mask = _mask(F, P, 0.3, 9)
    mask[:, :2] = True
    assert ((~mask).sum(1) > 1).any()
    W0 = np.where(np.repeat(mask, 2, axis=0), W, 0.0)
    prior = interpolate_in_time(W0, mask)
    N = np.linalg.qr(np.random.default_rng(10).standard_normal((P, 1)))[0]
    floor = 1e-24 * float((W0**2).mean())
    full = _fill(W0, prior, mask, N, floor)
    exact = _fill_by_constraint(W0, prior, mask, N)
    np.testing.assert_allclose(full, exact, rtol=0, atol=1e-9 * np.abs(W).max())
    # moderate noise: the normal equations are well conditioned there, and agree
    noise = 1e-2 * float((W0**2).mean())
    var = prior_variance(W0, mask)[::2]
    ref = W0.reshape(F, 2, P).copy()
    for f in np.flatnonzero((~mask).any(1)):
        idx = np.flatnonzero(~mask[f])
        A = N[idx] @ N[idx].T / noise + np.diag(1.0 / var[f, idx])
        for c in range(2):
            rhs = prior.reshape(F, 2, P)[f, c, idx] / var[f, idx] - N[idx] @ (ref[f, c] @ N) / noise
            ref[f, c, idx] = np.linalg.solve(A, rhs)
    np.testing.assert_allclose(_fill(W0, prior, mask, N, noise), ref.reshape(2 * F, P), rtol=1e-10,
                               atol=1e-12 * np.abs(W).max())


def test_frames_to_the_nearest_sighting_match_the_direct_search():
    from lipgen.nrsfm.time_prior import _frames_to_sighting

    rng = np.random.default_rng(11)
    for F, P, frac in ((200, 9, 0.1), (50, 7, 0.7), (5, 3, 0.5)):
        mask = rng.random((F, P)) > frac
        mask[rng.integers(F)] = True                       # every point seen at least once
        frames = np.arange(F)
        direct = np.stack([np.abs(frames[:, None] - np.flatnonzero(mask[:, p])[None, :]).min(1)
                           for p in range(P)], axis=1)
        assert np.array_equal(_frames_to_sighting(mask), direct)


def test_a_stopped_completion_goes_on_bit_for_bit():
    # noisy tracks: the iterations run past the caps below (a stopped completion is resumed by k="auto")
    F, P, r = 40, 14, 8
    W = _low_rank(F, P, r, seed=5) + 0.3 * np.random.default_rng(6).standard_normal((2 * F, P))
    mask = _mask(F, P, 0.2, 7)
    full, misfit, info = complete_subspace(W, mask, r)
    assert 8 < info["steps"] < 100
    state = complete_subspace(W, mask, r, max_iter=3)[2]["state"]
    assert state.steps == 3 and not state.done
    complete_subspace(W, mask, r, max_iter=8, resume=state)
    assert state.steps == 8
    full2, misfit2, info2 = complete_subspace(W, mask, r, resume=state)
    assert full2.tobytes() == full.tobytes() and misfit2 == misfit
    assert info2["steps"] == info["steps"] and info2["cost"] == info["cost"]
    # a stopped completion is not the finished one, and a finished one runs no further step
    assert complete_subspace(W, mask, r, max_iter=3)[0].tobytes() != full.tobytes()
    assert state.done
    assert complete_subspace(W, mask, r, max_iter=200, resume=state)[2]["steps"] == info["steps"]


def test_a_completion_resumed_step_by_step_is_one_run():
    """Resumed one step at a time, every step starts from a recomputed normal matrix (as every step did
    before the last step's was skipped): the same bytes, steps and costs as one run to convergence."""
    F, P, r = 30, 12, 5
    W = _low_rank(F, P, r, seed=11) + 0.2 * np.random.default_rng(12).standard_normal((2 * F, P))
    mask = _mask(F, P, 0.15, 13)
    full, misfit, info = complete_subspace(W, mask, r)
    assert 3 < info["steps"] < 100
    state = complete_subspace(W, mask, r, max_iter=1)[2]["state"]
    cap = 1
    while not state.done:
        cap += 1
        full2, misfit2, info2 = complete_subspace(W, mask, r, max_iter=cap, resume=state)
    assert full2.tobytes() == full.tobytes() and misfit2 == misfit
    assert info2["steps"] == info["steps"] and info2["cost"] == info["cost"]


def test_kept_residual_terms_give_the_values_of_a_fresh_evaluation():
    """The normal matrix reuses the residual terms of the last N only when N holds the same values
    (also after N is changed in place), and then gives a fresh evaluation's bytes."""
    F, P, r = 25, 11, 4
    W = _low_rank(F, P, r, seed=14) + 0.1 * np.random.default_rng(15).standard_normal((2 * F, P))
    mask = _mask(F, P, 0.2, 16)
    W0 = np.where(np.repeat(mask, 2, axis=0), W, 0.0)
    d = P - 1 - r
    rng = np.random.default_rng(17)
    N, Y = _bases(rng.standard_normal((P, d)))
    other = _bases(rng.standard_normal((P, d)))[0]

    def fresh(N):
        return _Frames(W0, mask, d).evaluate(N, Y)

    frames = _Frames(W0, mask, d)
    for first in (N, other):   # the same N before (terms reused), or another one (not reused)
        cost = frames.evaluate(first)
        assert cost == fresh(first)[0]
        got, want = frames.evaluate(N, Y), fresh(N)
        assert all(np.array_equal(a, b) for a, b in zip(got, want, strict=True))
    N[3] += 0.01                # changed in place: not the kept terms
    got, want = frames.evaluate(N, Y), fresh(N.copy())
    assert all(np.array_equal(a, b) for a, b in zip(got, want, strict=True))


def test_a_resumed_completion_must_be_the_same_call():
    F, P, r = 20, 10, 4
    W = _low_rank(F, P, r, seed=8) + 0.3 * np.random.default_rng(9).standard_normal((2 * F, P))
    mask = _mask(F, P, 0.2, 10)
    state = complete_subspace(W, mask, r, max_iter=3)[2]["state"]
    other = mask.copy()
    other[np.flatnonzero(mask[:, 5])[0], 5] = False
    for args, kwargs, match in (((W, other, r), {}, "another completion"),
                                ((W, mask, r - 1), {}, "another completion"),
                                ((W, mask, r), {"tol": 1e-6}, "another completion"),
                                ((W + 1.0, mask, r), {}, "another completion"),
                                ((W, mask, r), {"max_iter": 2}, "already run 3 steps")):
        with pytest.raises(ValueError, match=match):
            complete_subspace(*args, resume=state, **kwargs)
    with pytest.raises(TypeError, match="SubspaceCompletion"):
        complete_subspace(W, mask, r, resume={"steps": 3})
    for bad in (-1, 2.5, True):
        with pytest.raises(ValueError, match="max_iter"):
            complete_subspace(W, mask, r, max_iter=bad)
    assert state.steps == 3   # a refused call changes nothing


@pytest.mark.parametrize("eps", [0.0, 1e-13])
def test_hidden_points_the_model_leaves_partly_free_do_not_stop_the_completion(eps):
    """Two hidden points whose rows of N are equal (eps 0: N_H N_H^T is singular, numpy's inverse
    refuses it; body 1002 with gaps met this under a 1e-14 perturbation) or nearly (1e-13: the
    inverse is computed but wrong, its cost 20 % off). The cost is each row's distance to the
    reachable set, min_x |a + x N_H|, with N_H's directions under 1e-6 of its largest left out, and
    the Gauss-Newton terms stay finite."""
    F, P, d = 8, 10, 6
    rng = np.random.default_rng(5)
    W = rng.standard_normal((2 * F, P))
    mask = np.ones((F, P), dtype=bool)
    mask[:4, [2, 5]] = False
    N = rng.standard_normal((P, d))
    N[5] = N[2] + eps * rng.standard_normal(d)
    if eps == 0:
        with pytest.raises(np.linalg.LinAlgError):
            np.linalg.inv(N[[2, 5]] @ N[[2, 5]].T)
    W0 = np.where(np.repeat(mask, 2, axis=0), W, 0.0)
    frames = _Frames(W0, mask, d)
    direct = 0.0
    for f in range(F):
        NH = N[~mask[f]]
        for row in (2 * f, 2 * f + 1):
            a = W0[row] @ N
            x = np.linalg.lstsq(NH.T, -a, rcond=1e-6)[0] if len(NH) else np.zeros(0)
            direct += 0.5 * float(((a + x @ NH) ** 2).sum())
    assert frames.evaluate(N) == pytest.approx(direct, rel=1e-9)
    cost, JtJ, g = frames.evaluate(N, rng.standard_normal((P, 3)))
    assert cost == pytest.approx(direct, rel=1e-9)
    assert np.isfinite(JtJ).all() and np.isfinite(g).all()


def test_only_the_frames_that_need_it_take_the_pseudo_inverse():
    """A stack with one singular Gram matrix: the others keep numpy's plain inverse, bit for bit."""
    from lipgen.nrsfm.completion import _inverse_or_pseudo

    rng = np.random.default_rng(6)
    A = rng.standard_normal((5, 3, 7))
    A[2, 1] = A[2, 0]
    G = A @ A.transpose(0, 2, 1)
    out = _inverse_or_pseudo(G)
    keep = np.arange(5) != 2
    assert np.array_equal(out[keep], np.linalg.inv(G[keep]))
    np.testing.assert_allclose(out[2], np.linalg.pinv(G[2], hermitian=True), rtol=1e-8, atol=1e-12)


def test_a_rank_that_fits_every_row_completes_without_iterating():
    # 3K = P - 1 (16 tracked marks at K = 5, one mark of the 17 never tracked): the model fits any
    # centred row, says nothing about the hidden entries, and the run made no evaluator (it crashed
    # resetting one: 'SubspaceCompletion' object has no attribute 'frames')
    rng = np.random.default_rng(3)
    F, P = 30, 16
    W = rng.normal(size=(2 * F, P))
    mask = rng.random((F, P)) > 0.2
    full, misfit, info = complete_subspace(W, mask, P - 1, max_iter=50)
    seen = np.repeat(mask, 2, axis=0)
    assert np.array_equal(full[seen], W[seen]) and np.isfinite(full).all()
    assert info["steps"] == 0 and misfit == pytest.approx(0.0, abs=1e-9)
    # resumed with a higher cap: still nothing to do, and no error
    full2, _, _ = complete_subspace(W, mask, P - 1, max_iter=60, resume=info["state"])
    assert np.array_equal(full, full2)
    # and through the methods: dai at K = 5 on 16 points with a fifth of the entries hidden
    from lipgen.nrsfm import reconstruct
    from lipgen.nrsfm.synthetic import low_rank_sequence

    Wk = low_rank_sequence(F, P, 2, np.random.default_rng(1))[0]
    rec = reconstruct(Wk, 5, visible=mask)
    assert np.isfinite(rec.S).all()


def test_a_start_near_the_answer_saves_steps_and_keeps_the_answer():
    # noisy tracks, which take many steps from the time prior; started from the finished fill (the
    # model blended with the time prior, so near the answer, not on it) the fit takes half as many
    # steps to the same model (measured: 49 and 23); a start only moves where the iterations begin
    F, P, r = 40, 14, 8
    W = _low_rank(F, P, r, seed=5) + 0.3 * np.random.default_rng(6).standard_normal((2 * F, P))
    mask = _mask(F, P, 0.2, 7)
    cold, misfit, info = complete_subspace(W, mask, r)
    warm, misfit_w, info_w = complete_subspace(W, mask, r, start=cold)
    assert info_w["steps"] < info["steps"] / 2 and info_w["cost"][0] < info["cost"][0] / 2
    assert abs(misfit_w - misfit) < 1e-8 * misfit
    assert np.abs(warm - cold).max() < 1e-4 * np.abs(W).max()


def test_a_half_started_from_the_whole_sequence_is_filled_exactly_in_a_few_steps():
    # the even frames of exact low-rank tracks, started from the whole sequence's completion
    F, P, r = 120, 20, 6
    W = _low_rank(F, P, r, seed=8)
    mask = _mask(F, P, 0.25, 9)
    whole = complete_subspace(W, mask, r)[0]
    rows = np.arange(2 * F).reshape(F, 2)[0::2].ravel()
    cold, _, info = complete_subspace(W[rows], mask[0::2], r)
    warm, misfit, info_w = complete_subspace(W[rows], mask[0::2], r, start=whole)
    assert misfit < 1e-10 and info_w["steps"] < info["steps"]
    assert np.abs(warm - W[rows]).max() < 1e-6 * np.abs(W).max()


def test_a_start_must_be_complete_rows_over_the_same_points_and_not_resume():
    F, P, r = 40, 14, 8
    W = _low_rank(F, P, r, seed=5)
    mask = _mask(F, P, 0.2, 7)
    for bad, words in ((np.zeros((12, P + 1)), r"shape \(12, 15\)"), (np.zeros(P), r"shape \(14,\)"),
                       (np.zeros((r, P)), r"more than the rank 8.*shape \(8, 14\)"),
                       (np.full((10, P), np.nan), "140 NaN")):
        with pytest.raises(ValueError, match=words):
            complete_subspace(W, mask, r, start=bad)
    state = complete_subspace(W, mask, r, max_iter=2)[2]["state"]
    with pytest.raises(ValueError, match="start is for a new completion"):
        complete_subspace(W, mask, r, resume=state, start=W)


def test_the_normal_matrix_is_exactly_symmetric_from_its_upper_triangles():
    # built from the upper triangles of its symmetric factors (a quarter of the products), with hidden
    # points in some frames and none in others, r != d
    F, P, r = 30, 11, 3
    W = _low_rank(F, P, r) + 0.05 * np.random.default_rng(4).standard_normal((2 * F, P))
    mask = _mask(F, P, 0.15, 5)
    d = P - 1 - r
    N, Y = _bases(np.random.default_rng(6).standard_normal((P, d)))
    frames = _Frames(np.where(np.repeat(mask, 2, axis=0), W, 0.0), mask, d)
    assert {idx.shape[1] for idx, _ in frames.groups} >= {0, 1, 2}
    _, JtJ, _ = frames.evaluate(N, Y)
    # the plain sum over every (l, m, j, k), written out
    full = np.zeros((r, d, r, d))
    for idx, rows in frames.groups:
        for i, row in zip(idx, rows, strict=True):
            NH, YH = N[i], Y[i]
            G = np.linalg.inv(NH @ NH.T) if len(i) else np.zeros((0, 0))
            Pi = np.eye(d) - NH.T @ G @ NH
            for w in row:
                a = w @ N
                x = -G @ NH @ a                                   # the hidden entries' least-squares fill
                beta = w @ Y + x @ YH
                res = Pi @ a
                full += np.einsum("l,m,jk->ljmk", beta, beta, Pi)
                full += np.einsum("lm,j,k->ljmk", YH.T @ G @ YH, res, res)
    assert np.array_equal(JtJ, JtJ.T)
    assert np.allclose(JtJ, full.reshape(r * d, r * d), rtol=1e-12, atol=1e-12 * np.abs(full).max())


def test_a_damped_step_is_the_solve_and_a_failed_factorisation_damps_more(monkeypatch):
    import lipgen.nrsfm.completion as completion

    rng = np.random.default_rng(7)
    A = rng.standard_normal((20, 20))
    JtJ, g = A @ A.T, rng.standard_normal(20)
    diag = np.diag(JtJ).copy()
    step = completion._damped_step(JtJ, diag, 1e-3, g)
    assert np.allclose(step, np.linalg.solve(JtJ + 1e-3 * np.diag(diag), -g), rtol=1e-10)
    with pytest.raises(np.linalg.LinAlgError):
        completion._damped_step(-JtJ, diag, 1e-3, g)      # not positive definite
    # a factorisation that fails counts as a rejected step: the completion goes on with more damping
    F, P, r = 40, 12, 4
    W = _low_rank(F, P, r)
    mask = _mask(F, P, 0.1, 8)
    plain = complete_subspace(W, mask, r)
    calls, real = [], completion._damped_step

    def failing_twice(*args):
        calls.append(args[2])
        if len(calls) <= 2:
            raise np.linalg.LinAlgError("not positive definite")
        return real(*args)

    monkeypatch.setattr(completion, "_damped_step", failing_twice)
    full, misfit, _ = complete_subspace(W, mask, r)
    assert calls[1] == pytest.approx(10 * calls[0]) and calls[2] == pytest.approx(100 * calls[0])
    assert misfit < 1e-8 and np.allclose(full, plain[0], atol=1e-6 * np.abs(W).max())
