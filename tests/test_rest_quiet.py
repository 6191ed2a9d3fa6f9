"""The subject's rest from the quiet frames of a recording (lipgen.recon.rest)."""

import numpy as np
import pytest

from lipgen.recon.rest import quiet_frames, quiet_rest


def _speech(F=150, P=16, seed=0):
    """Markers that rest (plus noise) in pauses and move through random syllable targets between."""
    rng = np.random.default_rng(seed)
    rest = rng.normal(0, 10, (P, 3))
    dirs = rng.normal(0, 3, (4, P, 3))
    act = np.zeros((F + 40, 4))
    t = 0
    while t < F:
        n = rng.integers(15, 30)  # a phrase of moving syllables, then a pause of 8 frames
        phase = np.arange(n)
        act[t:t + n] = np.abs(np.sin(np.pi * phase / 6.0))[:, None] * rng.uniform(0.5, 1.5, 4)
        t += n + 8
    X = rest + np.einsum("fa,apk->fpk", act[:F], dirs)
    return X, rest, act[:F]


def test_quiet_frames_are_pause_frames_and_rest_is_recovered():
    X, rest, act = _speech()
    noisy = X + np.random.default_rng(1).normal(0, 0.05, X.shape)
    vis = np.ones(X.shape[:2], bool)
    q = quiet_frames(noisy, vis, share=0.15)
    assert 0 < np.mean(act[q].max(1) > 0.3) < 0.5  # held targets are quiet too, pauses more often
    est = quiet_rest(noisy, vis, share=0.15)
    assert np.sqrt(np.mean((est - rest) ** 2)) < 0.1
    # the median of all frames is pulled by the motion
    assert np.sqrt(np.mean((np.median(noisy, 0) - rest) ** 2)) > 1.0


def test_quiet_rest_unmeasured_marker_is_nan_and_bad_share_refused():
    X, rest, _ = _speech()
    vis = np.ones(X.shape[:2], bool)
    vis[:, 3] = False
    est = quiet_rest(X, vis)
    assert np.isnan(est[3]).all() and np.isfinite(np.delete(est, 3, 0)).all()
    with pytest.raises(ValueError, match="share"):
        quiet_frames(X, vis, share=0.0)
    with pytest.raises(ValueError, match="measured must have shape"):
        quiet_frames(X, vis[:, :5])
