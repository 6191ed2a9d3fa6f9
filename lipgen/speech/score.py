"""Scores of estimated phones against the truth: boundary errors, phone error rate, viseme
agreement per frame; and speech-shaped noise at a given SNR."""

from __future__ import annotations

import numpy as np

from lipgen.speech.audio import Audio
from lipgen.speech.phones import PhoneTrack
from lipgen.speech.visemes import frame_visemes

__all__ = ["edit_alignment", "boundary_errors", "phone_error_rate", "viseme_agreement",
           "speech_shaped_noise"]


def edit_alignment(a: list[str], b: list[str]) -> tuple[int, list[tuple[int, int]]]:
    """Levenshtein distance of label lists and the (i, j) pairs it aligns (matches and
    substitutions), by dynamic programming."""
    n, m = len(a), len(b)
    D = np.zeros((n + 1, m + 1), dtype=np.int64)
    D[:, 0], D[0, :] = np.arange(n + 1), np.arange(m + 1)
    for i in range(1, n + 1):
        for j in range(1, m + 1):
            D[i, j] = min(D[i - 1, j] + 1, D[i, j - 1] + 1, D[i - 1, j - 1] + (a[i - 1] != b[j - 1]))
    pairs, i, j = [], n, m
    while i > 0 and j > 0:
        if D[i, j] == D[i - 1, j - 1] + (a[i - 1] != b[j - 1]):
            pairs.append((i - 1, j - 1))
            i, j = i - 1, j - 1
        elif D[i, j] == D[i - 1, j] + 1:
            i -= 1
        else:
            j -= 1
    return int(D[n, m]), pairs[::-1]


def _speech(track: PhoneTrack) -> tuple[list[str], np.ndarray]:
    keep = [k for k, p in enumerate(track.labels) if p != "SIL"]
    return [track.labels[k] for k in keep], track.start[keep]


def boundary_errors(truth: PhoneTrack, estimate: PhoneTrack) -> tuple[np.ndarray, float]:
    """(|start error| (s) of each aligned phone pair, share of the truth's phones matched exactly).

    Pauses are left out; the phone sequences are paired by :func:`edit_alignment`, so a phone the
    dictionary pronounces differently from the truth still gives its boundary."""
    a, ta = _speech(truth)
    b, tb = _speech(estimate)
    _, pairs = edit_alignment(a, b)
    err = np.array([abs(tb[j] - ta[i]) for i, j in pairs])
    same = sum(a[i] == b[j] for i, j in pairs)
    return err, same / max(len(a), 1)


def phone_error_rate(truth: PhoneTrack, estimate: PhoneTrack) -> float:
    """Edit distance of the phone sequences (pauses left out) over the truth's length."""
    a, _ = _speech(truth)
    b, _ = _speech(estimate)
    return edit_alignment(a, b)[0] / max(len(a), 1)


def viseme_agreement(truth: PhoneTrack, estimate: PhoneTrack, fps: float = 30.0) -> float:
    """Share of frames (at ``fps`` over the truth's duration) whose viseme is the truth's."""
    n = max(1, int(truth.duration * fps))
    a, b = frame_visemes(truth, fps, n), frame_visemes(estimate, fps, n)
    return float(np.mean([x == y for x, y in zip(a, b, strict=True)]))


def speech_shaped_noise(audio: Audio, snr_db: float, seed=0) -> Audio:
    """``audio`` plus stationary noise with the speech's own long-term spectrum at ``snr_db`` dB.

    The noise is the speech's magnitude spectrum with random phases (seeded), scaled so that the
    ratio of the mean powers of speech and noise is ``snr_db``."""
    x = audio.samples
    spec = np.abs(np.fft.rfft(x))
    phase = np.random.default_rng(seed).uniform(0, 2 * np.pi, len(spec))
    noise = np.fft.irfft(spec * np.exp(1j * phase), n=len(x))
    noise *= np.sqrt(np.mean(x**2) / np.mean(noise**2)) * 10 ** (-snr_db / 20)
    y = x + noise
    peak = np.abs(y).max()
    y = y / peak * 0.9 if peak > 1.0 else y
    return Audio(y, audio.rate, f"{audio.source}+noise{snr_db:g}dB", audio.source_rate)
