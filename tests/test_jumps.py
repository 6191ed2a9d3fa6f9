"""The 3-D step check (recon.jumps): a jump along the epipolar line is caught, true motion is not."""

import numpy as np
import pytest

from lipgen.recon.jumps import StepLimit


def _run(points):
    """Feed a (F, P, 3) sequence through a StepLimit as track_raw_frames does; (F, P) jump flags."""
    F, P, _ = points.shape
    lim = StepLimit(P)
    last, since = np.full((P, 3), np.nan), np.ones(P)
    flags = np.zeros((F, P), dtype=bool)
    for t in range(F):
        jump = lim.check(points[t], last, since)
        flags[t] = jump
        kept = np.isfinite(points[t, :, 0]) & ~jump
        since[kept] = 0
        since += 1
        last[kept] = points[t, kept]
    return flags, lim


def test_a_synthetic_jump_is_caught_and_fast_true_motion_is_not():
    rng = np.random.default_rng(3)
    F = 60
    t = np.arange(F)[:, None]
    nose = np.hstack([0.3 * np.sin(t / 9), 0.2 * np.cos(t / 7), 0 * t]) + rng.normal(0, 0.05, (F, 3))
    # a lower-lip marker opening and closing fast: steps up to ~6.4 mm/frame (the hard preset's most)
    lip = np.hstack([0 * t, -13 * (1 - np.cos(t * 2 * np.pi / 6)) / 2, 0 * t]) + rng.normal(0, 0.05, (F, 3))
    steps = np.linalg.norm(np.diff(lip, axis=0), axis=1)
    assert 5.5 < steps.max() < 7
    pts = np.stack([nose, lip], axis=1)
    pts[30:34, 0] += [0, 0, 3.0]                   # the nose pair slides 3 mm in depth for 4 frames
    pts[10, 1] = np.nan                            # a lost frame: the step spans two frames
    flags, lim = _run(pts)
    assert flags[30:34, 0].all(), "the jump and the frames stuck on the wrong dot are taken back"
    assert not flags[:30, 0].any() and not flags[34:, 0].any()
    assert not flags[:, 1].any(), "true lip motion is never taken for a jump"
    lo = lim.limits()
    assert lo[0] == pytest.approx(lim.floor) and lo[1] > 6.4


def test_until_learned_the_limit_is_max_step_and_bad_settings_are_refused():
    lim = StepLimit(2, max_step=12.0, min_samples=8)
    np.testing.assert_array_equal(lim.limits(), [12.0, 12.0])
    jump = lim.check(np.array([[0, 0, 13.0], [0, 0, 5.0]]), np.zeros((2, 3)), np.array([1, 2]))
    np.testing.assert_array_equal(jump, [True, False])
    with pytest.raises(ValueError, match="must both be"):
        lim.check(np.zeros((3, 3)), np.zeros((3, 3)), np.ones(3))
    for kw in ({"k": 0}, {"floor": np.nan}, {"quantile": 1.5}, {"floor": 20.0}):
        with pytest.raises(ValueError, match="StepLimit"):
            StepLimit(2, **kw)
