"""The LLSE keeps a low-rank prior's gain in factored form (issue 22): same estimate, cheaper."""

from __future__ import annotations

import numpy as np
import pytest

from lipgen.modes.llse import LLSE, LowRankCovariance


def _eq_4_7(L, dofs, mean, R, Y):
    """Eq 4.7 from the dense covariance: x̄ + Λ[:, o] (Λ[o, o] + R)⁺ (y − x̄[o])."""
    P = np.linalg.pinv(L[np.ix_(dofs, dofs)] + np.diag(R), rcond=1e-10, hermitian=True)
    return mean + (Y - mean[dofs]) @ (L[:, dofs] @ P).T


@pytest.mark.parametrize("noise", [0.0, 0.05])
def test_factored_gain_matches_eq_4_7(noise):
    rng = np.random.default_rng(1)
    r, n = 6, 40
    B = rng.normal(size=(r, 3 * n))
    mean = rng.normal(size=3 * n)
    dofs = np.array([0, 1, 2, 10, 11, 30, 31, 32, 50, 51, 52, 80, 90, 100, 110, 119])
    est = LLSE.build(LowRankCovariance(B), dofs, mean=mean, noise=noise)
    assert est.lowrank is not None  # r + 1 = 7 of d = 16 observations: factored
    Y = rng.normal(size=(5, len(dofs)))
    want = _eq_4_7(B.T @ B, dofs, mean, np.full(len(dofs), noise), Y)
    got = est.estimate(Y)
    assert got.shape == (5, n, 3)
    assert np.allclose(got.reshape(5, -1), want, atol=1e-9 * np.abs(want).max())
    # one frame, and the dense gain it still carries (posterior, mixtures) agree with it
    assert np.allclose(est.estimate(Y[0]), got[0], rtol=0, atol=1e-12)
    assert np.allclose(Y @ est.gain_t + est.offset, got.reshape(5, -1), atol=1e-10)


def test_dense_gain_when_the_rank_is_not_small():
    rng = np.random.default_rng(2)
    B = rng.normal(size=(12, 30))
    dofs = np.arange(0, 30, 2)  # d = 15 < (r + 1) / 0.75
    est = LLSE.build(LowRankCovariance(B), dofs)
    assert est.lowrank is None
    Y = rng.normal(size=(3, len(dofs)))
    want = _eq_4_7(B.T @ B, dofs, np.zeros(30), np.zeros(len(dofs)), Y)
    assert np.allclose(est.estimate(Y).reshape(3, -1), want, atol=1e-9 * np.abs(want).max())


def test_mode_model_llse_is_factored_and_interpolates():
    from lipgen import lip_mesh
    from lipgen.fem import dofs
    from lipgen.modes.model import ModeModel

    mesh = lip_mesh(0)
    rng = np.random.default_rng(3)
    X = rng.normal(size=(40, 8)) @ rng.normal(size=(8, mesh.n_dofs))
    model = ModeModel(10).fit(X)
    d = dofs(mesh.markers)
    est = model.llse(d)
    assert est.lowrank is not None and est.lowrank[0].shape == (len(d), len(model.components_))
    # a field inside the model's span is recovered from its 48 observed DOFs
    x = model.mean_ + rng.normal(size=len(model.components_)) @ model.components_
    assert np.allclose(est.estimate(x[d]).ravel(), x, atol=1e-8 * np.abs(x).max())


def test_bad_values_still_rejected():
    est = LLSE.build(LowRankCovariance(np.random.default_rng(0).normal(size=(2, 30))), np.arange(9))
    with pytest.raises(ValueError, match=r"\(9,\) or \(b, 9\)"):
        est.estimate(np.zeros(8))
    with pytest.raises(ValueError, match="NaN or inf"):
        est.estimate(np.full(9, np.nan))
