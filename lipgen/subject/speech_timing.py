"""Random speech for the synthetic subject: syllables at a speaking rate, with coarticulation.

:func:`random_speech` strings random consonant-vowel syllables (visemes of
:data:`lipgen.subject.activation.VISEMES`) at a speaking rate of about 4-7 syllables per second,
with phrase pauses and per-syllable stress, and turns the sequence of viseme targets into
activations through a critically damped second-order response of time constant ``tau``: each
articulator moves toward its current target as a point attractor, so neighbouring visemes
overlap (coarticulation) and short ones are not fully reached (undershoot).

Sources for the timing
----------------------
- Speaking rate: conversational English runs at about 4-7 syllables per second (e.g. Jacewicz,
  Fox & Wei, "Between-speaker and within-speaker variation in speech tempo of American English",
  JASA 128, 2010: about 5 syllables/s in read and spontaneous speech); the fastest repeated
  syllables (diadochokinetic rate) of healthy adults are about 6-8 per second (Kent, Kent &
  Rosenbek, "Maximum performance tests of speech production", JSHD 52, 1987). Rates above 8 or
  below 1 syllable per second are refused as not speech.
- Coarticulation: articulator gestures as critically damped point attractors (Saltzman & Munhall,
  "A dynamical approach to gestural patterning in speech production", Ecological Psychology 1,
  1989); lip and jaw opening and closing movements in speech take about 100-200 ms (Ostry &
  Munhall, "Control of rate and duration of speech movements", JASA 77, 1985), which a critically
  damped response with ``tau`` = 30-50 ms reproduces (it covers 90 % of a step in about 3.9 tau).
"""

from __future__ import annotations

import numpy as np

from lipgen.subject.activation import DEFAULT_FPS, _check_fps, _viseme_vector

__all__ = ["random_speech", "coarticulate", "SPEECH_RATE_LIMITS", "DEFAULT_TAU"]

SPEECH_RATE_LIMITS = (1.0, 8.0)
"""Syllables per second accepted by :func:`random_speech` (see the module docstring)."""

DEFAULT_TAU = 0.04
"""Coarticulation time constant, seconds (a 90 % step in about 160 ms)."""

_VOWELS = ("AA", "AE", "AH", "EH", "EE", "IH", "OH", "OO")
_CONSONANTS = ("M", "F", "TH", "S", "SH", "L", "R", "W", "REST")  # REST: a vowel-initial syllable


def coarticulate(targets: np.ndarray, fps: float, tau: float = DEFAULT_TAU) -> np.ndarray:
    """(F, A) activations: each column of ``targets`` (F, A) followed by a critically damped
    second-order system of time constant ``tau`` seconds, starting at rest (exact discretisation
    of ``x'' = (target - x)/tau^2 - 2 x'/tau`` with the target held over each frame)."""
    fps = _check_fps(fps)
    if not np.isfinite(tau) or not 0.005 <= tau <= 0.5:
        raise ValueError(f"tau must be a time constant in [0.005, 0.5] s, got {tau}")
    h = 1.0 / fps
    a = h / tau
    e = np.exp(-a)
    # state transition of (x - target, v) over one frame for the critically damped system
    Phi = e * np.array([[1 + a, h], [-a / tau, 1 - a]])
    x = np.zeros(targets.shape[1])
    v = np.zeros_like(x)
    out = np.empty_like(targets, dtype=float)
    for f, goal in enumerate(targets):
        d = x - goal
        d, v = Phi[0, 0] * d + Phi[0, 1] * v, Phi[1, 0] * d + Phi[1, 1] * v
        x = goal + d
        out[f] = x
    return out


def random_speech(n_frames: int, seed=0, fps: float = DEFAULT_FPS, syllables_per_second: float = 5.0,
                  tau: float = DEFAULT_TAU) -> tuple[np.ndarray, list[tuple[str, float]]]:
    """Random speech: activations ``(F, A)`` and the viseme sequence ``[(viseme, seconds), ...]``.

    Each syllable is a consonant then a vowel viseme (the consonant about a third of it); syllable
    durations vary log-normally (20 %) around ``1 / syllables_per_second``; a phrase pause of
    0.2-0.5 s follows every 3-8 syllables; each syllable is stressed by a factor 0.7-1.2.
    """
    n_frames = int(n_frames)
    if n_frames < 1:
        raise ValueError(f"n_frames must be >= 1, got {n_frames}")
    fps = _check_fps(fps)
    lo, hi = SPEECH_RATE_LIMITS
    rate = float(syllables_per_second)
    if not np.isfinite(rate) or not lo <= rate <= hi:
        raise ValueError(f"a speech rate of {syllables_per_second} syllables/s is impossible; speech runs at "
                         f"{lo:g}-{hi:g} syllables/s (conversation 4-7)")
    rng = np.random.default_rng(seed)
    total = n_frames / fps
    seq: list[tuple[str, float, float]] = []  # (viseme, seconds, stress)
    t, until_pause = 0.0, int(rng.integers(3, 9))
    while t < total:
        dur = float(np.exp(rng.normal(np.log(1.0 / rate), 0.2)))
        stress = float(rng.uniform(0.7, 1.2))
        c, v = _CONSONANTS[rng.integers(len(_CONSONANTS))], _VOWELS[rng.integers(len(_VOWELS))]
        seq += [(c, dur / 3, stress), (v, 2 * dur / 3, stress)]
        t += dur
        until_pause -= 1
        if until_pause == 0:
            pause = float(rng.uniform(0.2, 0.5))
            seq.append(("REST", pause, 1.0))
            t += pause
            until_pause = int(rng.integers(3, 9))
    ends = np.cumsum([s for _, s, _ in seq])
    times = (np.arange(n_frames) + 0.5) / fps
    which = np.minimum(np.searchsorted(ends, times, side="right"), len(seq) - 1)
    table = np.stack([_viseme_vector(name) * k for name, _, k in seq])
    A = coarticulate(table[which], fps, tau)
    return np.clip(A, 0.0, 2.0), [(n, s) for n, s, _ in seq]
