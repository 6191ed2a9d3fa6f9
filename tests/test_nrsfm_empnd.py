"""EM-PND (lipgen.nrsfm.empnd): the constrained M-step against a dense KKT solve, exact recovery of
noise-free data of the model, monotone likelihood, determinism, bad input and extreme scales."""

import numpy as np
import pytest

from lipgen._threads import blas_threads
from lipgen.nrsfm import e3d, reconstruct
from lipgen.nrsfm._tracks import check_tracks
from lipgen.nrsfm.empnd import _constrained_blocks, _project_modes, em_pnd, procrustean_residual
from lipgen.nrsfm.synthetic import random_rotations


def _pnd_sequence(n_frames, n_points, k, seed, deformation=0.3):
    """Noise-free shapes of the model: a mean plus K modes that satisfy the Procrustean constraints,
    the weights centred (so that the mean shape is also the sample mean of the aligned shapes)."""
    rng = np.random.default_rng(seed)
    sbar = rng.standard_normal((3, n_points))
    sbar -= sbar.mean(axis=1, keepdims=True)
    V = _project_modes(sbar, deformation * rng.standard_normal((n_points, 3, k)))
    z = rng.standard_normal((n_frames, k))
    X = sbar[None] + np.einsum("pak,fk->fap", V, z - z.mean(axis=0))
    S = random_rotations(n_frames, rng) @ X
    W = (S[:, :2] + rng.standard_normal((n_frames, 2, 1))).reshape(2 * n_frames, n_points)
    return W, S.reshape(3 * n_frames, n_points), sbar, V


@pytest.mark.parametrize("shared", [False, True])
def test_constrained_step_matches_dense_kkt(shared):
    rng = np.random.default_rng(0)
    P, d, c = 7, 6, 5
    L = rng.standard_normal((P, d, d))
    N = L @ L.transpose(0, 2, 1) + d * np.eye(d)
    if shared:
        N = N[0]
    r, A = rng.standard_normal((P, d)), rng.standard_normal((c, P, d))
    x = _constrained_blocks(N, r, A)
    big = np.zeros((P * d, P * d))
    for p in range(P):
        big[p * d:(p + 1) * d, p * d:(p + 1) * d] = N if shared else N[p]
    Ad = A.reshape(c, P * d)
    kkt = np.block([[big, Ad.T], [Ad, np.zeros((c, c))]])
    ref = np.linalg.solve(kkt, np.concatenate([r.ravel(), np.zeros(c)]))[:P * d]
    assert np.allclose(x.ravel(), ref, rtol=0, atol=1e-10)
    assert np.abs(Ad @ x.ravel()).max() < 1e-10


def test_projected_modes_satisfy_the_procrustean_constraints():
    rng = np.random.default_rng(3)
    sbar = rng.standard_normal((3, 12))
    sbar -= sbar.mean(axis=1, keepdims=True)
    V = _project_modes(sbar, rng.standard_normal((12, 3, 3)))
    assert procrustean_residual(sbar, V) < 1e-13
    # a rotation of the mean (first order: skew(w) sbar) is not a deformation: projected to zero
    w = np.array([[0, -0.3, 0.2], [0.3, 0, -0.1], [-0.2, 0.1, 0]])
    assert np.abs(_project_modes(sbar, (w @ sbar).T[:, :, None])).max() < 1e-12


@pytest.mark.parametrize("k", [1, 2, 4])
def test_recovers_noise_free_data_of_the_model(k):
    W, S, _, _ = _pnd_sequence(80, 20, k, seed=10 + k)
    rec = reconstruct(W, k, method="em-pnd")
    assert rec.info["pnd_kept"] and rec.weights.shape == (80, k + 1)
    assert e3d(S_est=rec.S, S_true=S) < 1e-6
    assert rec.info["procrustean_residual"] < 1e-10


def test_likelihood_never_rises_and_constraints_hold_from_a_rigid_start():
    W, S, _, _ = _pnd_sequence(30, 12, 2, seed=5, deformation=0.2)
    W = W + 1e-3 * np.random.default_rng(1).standard_normal(W.shape)
    with blas_threads(1, always=True):  # tiny solves: threads would only wait (lipgen._threads)
        _, _, B, _, info = em_pnd(check_tracks(W), 2, max_iter=40)
    h = np.array(info["nll_history"])
    assert h[-1] < h[0] and (np.diff(h) <= 1e-9 * np.abs(h[:-1]).clip(1)).all()
    assert procrustean_residual(B[0], B[1:].transpose(2, 1, 0)) < 1e-10


def test_same_bits_whatever_threads_and_history():
    W, _, _, _ = _pnd_sequence(30, 12, 2, seed=7, deformation=0.4)
    W = W + 1e-2 * np.random.default_rng(2).standard_normal(W.shape)
    a = reconstruct(W, 2, method="em-pnd", em_iter=30)
    np.linalg.svd(np.random.default_rng(3).standard_normal((300, 300)))   # other work in between
    with blas_threads(2):
        b = reconstruct(W, 2, method="em-pnd", em_iter=30)
    assert np.array_equal(a.S, b.S) and np.array_equal(a.weights, b.weights)


@pytest.mark.parametrize("scale", [1e-300, 1e300])
def test_extreme_scales_are_normalised_and_solved(scale):
    W, S, _, _ = _pnd_sequence(40, 12, 1, seed=4)
    rec = reconstruct(W * scale, 1, method="em-pnd")
    assert np.isfinite(rec.S).all()
    assert e3d(S_est=rec.S, S_true=S * scale) < 1e-6


def test_bad_k_is_named():
    W, _, _, _ = _pnd_sequence(40, 12, 1, seed=4)
    with pytest.raises(ValueError, match="k=3 is too large for method 'em-pnd'"):
        reconstruct(W, 3, method="em-pnd")
    with pytest.raises(ValueError, match="at least 0"):
        reconstruct(W, -1, method="em-pnd")


def test_k_auto_picks_the_true_number_of_modes_by_bic():
    W, S, _, _ = _pnd_sequence(60, 16, 2, seed=8)
    rec = reconstruct(W, "auto", method="em-pnd", em_iter=100)
    choice = rec.info["k_choice"]
    assert choice["ks"] == [0, 1, 2, 4] and rec.k == 2 == choice["chosen"]
    assert e3d(S_est=rec.S, S_true=S) < 1e-6


def test_missing_points_noise_free():
    W, S, _, _ = _pnd_sequence(40, 12, 1, seed=9)
    visible = np.random.default_rng(4).random((40, 12)) > 0.1
    W = np.where(np.repeat(visible, 2, axis=0), W, np.nan)
    rec = reconstruct(W, 1, method="em-pnd", visible=visible)
    assert rec.info["pnd_kept"]
    assert e3d(S_est=rec.S, S_true=S) < 1e-6


def test_exact_low_rank_tracks_keep_dais_exact_fit():
    # rank-3K tracks whose modes break the Procrustean constraints: dai's K + 1 shapes reproduce
    # them exactly, EM-PND's constrained modes cannot, so the exact start is the answer
    from lipgen.nrsfm.synthetic import low_rank_sequence

    W, S, _ = low_rank_sequence(60, 15, 3, np.random.default_rng(12))
    rec = reconstruct(W, 2, method="em-pnd", em_iter=50)
    assert not rec.info["pnd_kept"] and rec.info["pnd_relative_reprojection"] > 1e-6
    assert e3d(S_est=rec.S, S_true=S) < 1e-6
