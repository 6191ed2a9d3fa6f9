"""Random speech: the rate it was asked for, coarticulation as a critically damped response."""

import numpy as np
import pytest

from lipgen.subject.activation import ACTIONS
from lipgen.subject.speech_timing import DEFAULT_TAU, coarticulate, random_speech


def test_a_step_follows_the_critically_damped_closed_form():
    fps, tau = 1000.0, 0.04
    targets = np.ones((400, 1))
    x = coarticulate(targets, fps, tau)[:, 0]
    t = (np.arange(400) + 1) / fps
    assert np.allclose(x, 1 - (1 + t / tau) * np.exp(-t / tau), atol=1e-12)
    assert (np.diff(x) >= 0).all() and x.max() <= 1.0  # no overshoot


@pytest.mark.parametrize("rate", [4.0, 5.5, 7.0])
def test_random_speech_runs_at_the_asked_rate_and_moves_the_jaw(rate):
    fps, n = 30.0, 600
    A, seq = random_speech(n, seed=1, fps=fps, syllables_per_second=rate)
    assert A.shape == (n, len(ACTIONS)) and (A >= 0).all() and (A <= 2).all()
    speech = sum(s for v, s in seq if v != "REST") / 1.0
    syllables = sum(1 for v, _ in seq if v not in ("REST",)) / 2  # roughly: C + V per syllable
    assert 0.75 * rate < syllables / max(speech, 1e-9) < 1.35 * rate
    # the jaw opens and closes: it moves over a good part of its range within the clip
    jaw = A[:, ACTIONS.index("jaw_open")]
    assert jaw.max() - jaw.min() > 0.3


def test_random_speech_is_seeded_and_coarticulated():
    a, _ = random_speech(90, seed=4)
    b, _ = random_speech(90, seed=4)
    c, _ = random_speech(90, seed=5)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    # a critically damped response with tau = 40 ms cannot jump: bounded frame-to-frame change
    assert np.abs(np.diff(a, axis=0)).max() < 0.6
    assert DEFAULT_TAU == pytest.approx(0.04)


def test_impossible_rates_are_refused():
    with pytest.raises(ValueError, match="12 syllables/s is impossible; speech runs at 1-8"):
        random_speech(30, syllables_per_second=12)
    with pytest.raises(ValueError, match="impossible"):
        random_speech(30, syllables_per_second=0.2)
    with pytest.raises(ValueError, match="tau"):
        random_speech(30, tau=2.0)
