"""Split-half reliability of the recovered depth and its shrinkage towards the flat answer
(lipgen.nrsfm.reliability), as the last step of k="auto"."""

import numpy as np
import pytest

from lipgen.experiments.nrsfm_benchmarks import flat_e3d
from lipgen.nrsfm import e3d, reconstruct
from lipgen.nrsfm.kchoice import shrink_unreliable_depth
from lipgen.nrsfm.reliability import MIN_HALF_FRAMES, _depth_correlation, shrink_depth, split_half_reliability
from lipgen.nrsfm.synthetic import low_rank_sequence
from lipgen.nrsfm.validation import human_sequence


def test_depth_correlation_closed_forms():
    rng = np.random.default_rng(0)
    v, w = rng.standard_normal(30), rng.standard_normal(30)
    z = np.arange(41)[:, None] * v + 3.0 * w            # depth linear in time: neighbours' mean is exact
    odd, even = z[1::2], z[0::2]
    assert _depth_correlation(odd, even) == pytest.approx(1.0, abs=1e-12)
    assert _depth_correlation(-odd, even) == pytest.approx(1.0, abs=1e-12)     # a half's global reflection
    # odd frames = the neighbours' mean plus noise of the same variance: rho = 1/2 in the limit
    b = 0.5 * (even[:-1] + even[1:])
    b = b - b.mean(axis=1, keepdims=True)
    noise = rng.standard_normal(b.shape) * np.sqrt(np.mean(b**2))
    rho = _depth_correlation(b + noise, even)
    assert rho == pytest.approx(1 / np.sqrt(2), abs=0.05)     # corr(x, x + e) = 1 / sqrt(2) at equal variance
    assert _depth_correlation(rng.standard_normal((200, 30)), rng.standard_normal((201, 30))) < 0.05
    assert _depth_correlation(np.zeros((5, 4)), np.ones((6, 4))) == 0.0


def test_shrink_depth_scales_the_depth_alone():
    s = human_sequence(300, 30)
    rec = reconstruct(s.W, 3)
    half = shrink_depth(rec, 0.5)
    tol = 1e-9 * np.abs(rec.shapes).max()
    np.testing.assert_allclose(half.shapes[:, :2], rec.shapes[:, :2], atol=tol)
    np.testing.assert_allclose(half.shapes[:, 2], 0.5 * rec.shapes[:, 2], atol=tol)
    np.testing.assert_allclose(half.reproject(), rec.reproject(), atol=1e-9 * np.abs(s.W).max())
    assert np.array_equal(half.rotations, rec.rotations) and half.info["depth_factor"] == 0.5
    assert shrink_depth(rec, 1.0) is rec
    # no depth at all is exactly the flat baseline
    assert e3d(S_est=shrink_depth(rec, 0.0).S, S_true=s.S) == pytest.approx(flat_e3d(s.W, s.S), rel=1e-9)
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="factor"):
            shrink_depth(rec, bad)


def test_exact_low_rank_depth_is_fully_reliable_and_kept():
    # a smooth turn: each half is exact, and the odd frames' depth differs from their neighbours' mean
    # only by the interpolation's error
    W, S, _ = low_rank_sequence(40, 15, 2, np.random.default_rng(4), smooth=True)
    rho, record = split_half_reliability(W, 2)
    assert rho > 0.999 and record["k"] == 2
    # frames unrelated in time (random rotations): an exact K-shape fit is kept without the halves
    W, S, _ = low_rank_sequence(40, 15, 2, np.random.default_rng(4))
    rec = shrink_unreliable_depth(W, reconstruct(W, 2))
    assert rec.info["depth_reliability"]["reason"].startswith("exact")
    assert e3d(S_est=rec.S, S_true=S) < 1e-6


def test_too_few_frames_keep_their_depth():
    W, _, _ = low_rank_sequence(2 * MIN_HALF_FRAMES - 1, 12, 1, np.random.default_rng(1))
    rho, record = split_half_reliability(W, 1)
    assert rho == 1.0 and record["k"] is None and "too short" in record["reason"]


def test_unreproducible_depth_is_shrunk_below_the_flat_baseline():
    """Development body dance-406 at 80 frames: dai's rotations at the automatic K (6) are wrong and its
    depth is worse than none (0.53 against flat 0.38); the even and odd frames do not agree on it
    (rho about 0.06), and the shrunk answer is below the flat baseline."""
    s = human_sequence(406, 80)
    flat = flat_e3d(s.W, s.S)
    rec = reconstruct(s.W, 6)
    assert e3d(S_est=rec.S, S_true=s.S) > flat
    shrunk = shrink_unreliable_depth(s.W, rec)
    assert shrunk.info["depth_reliability"]["rho"] < 0.3
    assert e3d(S_est=shrunk.S, S_true=s.S) < flat
