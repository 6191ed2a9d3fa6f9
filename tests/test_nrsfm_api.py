"""NRSfM API edges: very few frames, k="auto", e3d's keyword-only arguments, extreme scales."""

import numpy as np
import pytest

from lipgen.nrsfm import MEAN_PLUS_MODES, METHODS, e3d, reconstruct
from lipgen.nrsfm.synthetic import low_rank_sequence


@pytest.mark.parametrize("n_frames", [2, 3, 4])
@pytest.mark.parametrize("method", sorted(METHODS))
def test_few_frames_give_a_result_or_a_clear_error(n_frames, method):
    W, S, _ = low_rank_sequence(n_frames, 10, 1, np.random.default_rng(n_frames))
    k = 0 if method in MEAN_PLUS_MODES else 1
    if n_frames == 2:  # 2 frames x 10 points: 40 coordinates for 42 unknowns
        with pytest.raises(ValueError, match=r"k=1 gives 42 unknowns .* only 40 observed coordinates"):
            reconstruct(W, k, method=method)
        return
    rec = reconstruct(W, k, method=method)  # rigid: exact from 3 frames on
    assert e3d(S_est=rec.S, S_true=S) < 1e-6


def test_few_frames_with_missing_points():
    W, S, _ = low_rank_sequence(4, 12, 1, np.random.default_rng(0))
    visible = np.ones((4, 12), bool)
    visible[1, 3] = visible[2, 7] = False
    rec = reconstruct(np.where(np.repeat(visible, 2, axis=0), W, np.nan), 1, visible=visible)
    assert e3d(S_est=rec.S, S_true=S) < 1e-6


def test_k_auto_in_the_api():
    W, S, _ = low_rank_sequence(40, 12, 2, np.random.default_rng(1))
    rec = reconstruct(W, "auto")
    assert rec.k == 2 and rec.info["k_choice"]["chosen"] == 2  # the smallest K fitted exactly
    assert e3d(S_est=rec.S, S_true=S) < 1e-6
    assert reconstruct(W, "AUTO", method="em-ppca", em_iter=50).k == 1  # em-ppca: modes beyond the mean
    with pytest.raises(ValueError, match="integer .* or 'auto', got 'two'"):
        reconstruct(W, "two")
    with pytest.raises(TypeError, match="must be an integer"):
        reconstruct(W, 2.5)


def test_e3d_arguments_are_keyword_only():
    S = np.random.default_rng(2).standard_normal((9, 6))
    with pytest.raises(TypeError, match="keyword arguments only"):
        e3d(S, S)
    with pytest.raises(TypeError, match="S_true="):
        e3d(S_est=S)
    # not symmetric: s comes from the truth, so swapping would give another number
    assert e3d(S_est=2 * S, S_true=S) != pytest.approx(e3d(S_est=S, S_true=2 * S))


@pytest.mark.parametrize("scale", [1e-300, 1e-150, 1e150, 1e300])
def test_extreme_scales_are_normalised_and_solved(scale):
    W, S, _ = low_rank_sequence(30, 10, 2, np.random.default_rng(1))
    rec = reconstruct(W * scale, 2)
    assert np.isfinite(rec.S).all()
    assert e3d(S_est=rec.S, S_true=S * scale) < 1e-6
    assert rec.reprojection_rms < 1e-6 * scale
    assert np.allclose(rec.reproject(), W * scale, rtol=0, atol=1e-6 * scale * np.abs(W).max())


def test_power_of_two_scale_gives_the_same_weights_bit_for_bit():
    W, _, _ = low_rank_sequence(30, 10, 2, np.random.default_rng(1))
    a, b = reconstruct(W, 2), reconstruct(W * 2.0**-900, 2)
    assert np.array_equal(a.weights, b.weights) and np.array_equal(a.basis * 2.0**-900, b.basis)


def test_subnormal_scale_names_the_scale():
    W, _, _ = low_rank_sequence(30, 10, 2, np.random.default_rng(1))
    with pytest.raises(ValueError, match=r"no larger than .*e-310.*multiply W"):
        reconstruct(W * 1e-310, 2)



@pytest.mark.parametrize("method", ["dai", "em-pnd", "em-ppca"])
@pytest.mark.parametrize("scale", [2.0**-997, 2.0**-60, 2.0**700, 2.0**997])
def test_k_auto_solves_extreme_scales_as_the_ordinary_one(method, scale):
    # k="auto" chooses K and (dai) averages the depths of several Ks: at 1e-300 it used to refuse the
    # tracks as constant, at 1e300 it overflowed (RuntimeWarnings) and answered differently. A power of
    # two rescales exactly, so the answer is the ordinary one times the scale.
    import warnings

    W, _, _ = low_rank_sequence(20, 12, 2, np.random.default_rng(5))
    W = W + 0.01 * np.random.default_rng(6).standard_normal(W.shape)    # noisy: not an exact fit
    base = reconstruct(W, "auto", method=method)
    with warnings.catch_warnings():
        warnings.simplefilter("error")                                   # no overflow on the way
        rec = reconstruct(W * scale, "auto", method=method)
    assert rec.k == base.k and np.isfinite(rec.S).all()
    np.testing.assert_allclose(rec.S / scale, base.S, rtol=0, atol=1e-9 * np.abs(base.S).max())


@pytest.mark.parametrize("scale", [1e-300, 1e300])
def test_k_auto_solves_decimal_extremes_too(scale):
    W, S, _ = low_rank_sequence(30, 10, 2, np.random.default_rng(1))
    rec = reconstruct(W * scale, "auto")
    assert rec.k == 2 and e3d(S_est=rec.S, S_true=S * scale) < 1e-6
