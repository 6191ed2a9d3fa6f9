"""Reading speech audio: WAV files of any common rate and sample format, as 16 kHz mono.

PocketSphinx's en-US acoustic model is trained on 16 kHz speech, so every recording is mixed to
mono and resampled to :data:`RATE` (band-limited, by Fourier interpolation of the whole clip:
numpy's FFT, which spares the command scipy.signal's second-long import), and the log says so.
Formats read: RIFF/WAVE with integer PCM of 8, 16, 24 or 32 bits, or IEEE float of 32 or 64
bits, plain or ``WAVE_FORMAT_EXTENSIBLE``.
"""

from __future__ import annotations

import logging
import os
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lipgen.errors import LipgenError

__all__ = ["RATE", "Audio", "AudioError", "NoSpeechError", "read_wav", "write_wav", "as_audio",
           "check_speech", "resample"]

log = logging.getLogger(__name__)

RATE = 16000
"""Sample rate (Hz) of the audio handed to the recogniser."""

_PCM, _FLOAT, _EXTENSIBLE = 1, 3, 0xFFFE


class AudioError(LipgenError, ValueError):
    """An audio file that cannot be read: not a WAV, an unsupported sample format, or empty."""


class NoSpeechError(LipgenError, ValueError):
    """Audio that holds no speech (silence or near-silence)."""


@dataclass(frozen=True, eq=False)
class Audio:
    """Mono speech at :data:`RATE`.

    Attributes
    ----------
    samples : (s,) float
        Samples in [-1, 1].
    rate : int
        Samples per second (always :data:`RATE` after :func:`read_wav`).
    source : str
        Where it came from (a path, or a description).
    source_rate : int
        The rate of the original recording.
    """

    samples: np.ndarray
    rate: int = RATE
    source: str = "array"
    source_rate: int = RATE

    @property
    def duration(self) -> float:
        """Length in seconds."""
        return len(self.samples) / self.rate

    def pcm16(self) -> bytes:
        """Little-endian 16-bit PCM bytes, as the recogniser reads them."""
        return (np.clip(self.samples, -1.0, 1.0) * 32767.0).round().astype("<i2").tobytes()


def _chunks(data: bytes, path: str) -> dict[bytes, bytes]:
    if len(data) < 12 or data[:4] != b"RIFF" or data[8:12] != b"WAVE":
        raise AudioError(f"{path} is not a WAV file (no RIFF/WAVE header); convert it to WAV, e.g. "
                         f"`ffmpeg -i INPUT -ar 16000 -ac 1 out.wav`")
    out, pos = {}, 12
    while pos + 8 <= len(data):
        cid, size = data[pos:pos + 4], struct.unpack("<I", data[pos + 4:pos + 8])[0]
        out.setdefault(cid, data[pos + 8:pos + 8 + size])
        pos += 8 + size + (size & 1)
    for need in (b"fmt ", b"data"):
        if need not in out:
            raise AudioError(f"{path} is a damaged WAV file: it has no {need.decode().strip()!r} chunk")
    return out


def _decode(fmt: bytes, raw: bytes, path: str) -> tuple[np.ndarray, int]:
    """(samples (s, channels) float in [-1, 1], rate) from a WAV's fmt and data chunks."""
    if len(fmt) < 16:
        raise AudioError(f"{path}: the WAV format chunk is {len(fmt)} bytes, expected at least 16")
    tag, channels, rate, _, align, bits = struct.unpack("<HHIIHH", fmt[:16])
    if tag == _EXTENSIBLE and len(fmt) >= 26:
        tag = struct.unpack("<H", fmt[24:26])[0]  # the first two bytes of the sub-format GUID
    width = bits // 8
    if channels < 1 or rate < 1 or width < 1 or align != channels * width:
        raise AudioError(f"{path}: inconsistent WAV header (channels {channels}, rate {rate}, "
                         f"{bits} bits, block {align})")
    raw = raw[:len(raw) - len(raw) % align]
    if tag == _PCM and width in (1, 2, 4):
        kind = {1: "u1", 2: "<i2", 4: "<i4"}[width]
        x = np.frombuffer(raw, kind).astype(np.float64)
        x = (x - 128.0) / 128.0 if width == 1 else x / float(2 ** (bits - 1))
    elif tag == _PCM and width == 3:
        b = np.frombuffer(raw, np.uint8).reshape(-1, 3).astype(np.int32)
        x = ((b[:, 0] | (b[:, 1] << 8) | (b[:, 2] << 16)) << 8 >> 8).astype(np.float64) / 2.0**23
    elif tag == _FLOAT and width in (4, 8):
        x = np.frombuffer(raw, "<f4" if width == 4 else "<f8").astype(np.float64)
    else:
        raise AudioError(f"{path}: unsupported WAV sample format (format tag {tag}, {bits} bits); "
                         "lipgen reads integer PCM of 8/16/24/32 bits and float of 32/64 bits. "
                         "Convert it, e.g. `ffmpeg -i INPUT -ar 16000 -ac 1 -sample_fmt s16 out.wav`")
    if not np.isfinite(x).all():
        raise AudioError(f"{path}: the samples hold NaN or infinity")
    return x.reshape(-1, channels), rate


def as_audio(samples, rate: int, source: str = "array") -> Audio:
    """Mono 16 kHz :class:`Audio` from samples ``(s,)`` or ``(s, channels)`` at ``rate`` Hz.

    Channels are averaged; another rate is resampled to :data:`RATE` (logged).
    """
    x = np.asarray(samples, dtype=np.float64)
    if x.ndim not in (1, 2) or x.shape[0] == 0:
        raise AudioError(f"{source}: audio samples must have shape (s,) or (s, channels) with s > 0, "
                         f"got shape {x.shape}")
    if not np.isfinite(x).all():
        raise AudioError(f"{source}: the samples hold NaN or infinity")
    rate = int(rate)
    if not 1000 <= rate <= 384000:
        raise AudioError(f"{source}: sample rate {rate} Hz is outside 1 kHz .. 384 kHz")
    if x.ndim == 2:
        if x.shape[1] > 1:
            log.info("%s: mixing %d channels to mono", source, x.shape[1])
        x = x.mean(axis=1)
    if rate != RATE:
        log.info("%s: resampling %d Hz to %d Hz", source, rate, RATE)
        x = resample(x, rate, RATE)
    return Audio(x, RATE, source, rate)


def resample(x: np.ndarray, rate: int, new_rate: int) -> np.ndarray:
    """``x`` (s,) at ``rate`` Hz band-limited to and sampled at ``new_rate`` Hz (Fourier method:
    the spectrum is cut, or zero-padded, at the lower Nyquist frequency)."""
    n_out = max(1, int(round(len(x) * new_rate / rate)))
    X = np.fft.rfft(x)
    Y = np.zeros(n_out // 2 + 1, dtype=complex)
    k = min(len(X), len(Y))
    Y[:k] = X[:k]
    if k == len(Y) and n_out % 2 == 0 and n_out < len(x):
        Y[-1] = Y[-1].real  # the new Nyquist bin of a real signal
    return np.fft.irfft(Y, n_out) * (n_out / len(x))


def read_wav(path: str | os.PathLike) -> Audio:
    """Read a WAV file as mono 16 kHz :class:`Audio` (see the module doc for the formats).

    Raises
    ------
    FileNotFoundError
        No such file.
    AudioError
        Not a WAV file, an unsupported sample format, or no samples.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"audio file not found: {p}")
    chunks = _chunks(p.read_bytes(), str(p))
    x, rate = _decode(chunks[b"fmt "], chunks[b"data"], str(p))
    if len(x) == 0:
        raise AudioError(f"{p}: the WAV file holds no samples")
    return as_audio(x, rate, str(p))


def write_wav(path: str | os.PathLike, audio: Audio) -> None:
    """Write ``audio`` as a 16-bit mono PCM WAV at its rate (atomically)."""
    from lipgen._io import atomic_path

    pcm = audio.pcm16()
    header = (b"RIFF" + struct.pack("<I", 36 + len(pcm)) + b"WAVE"
              + b"fmt " + struct.pack("<IHHIIHH", 16, _PCM, 1, audio.rate, 2 * audio.rate, 2, 16)
              + b"data" + struct.pack("<I", len(pcm)))
    with atomic_path(path) as tmp:
        tmp.write_bytes(header + pcm)


def check_speech(audio: Audio, floor_db: float = -50.0) -> None:
    """Raise :class:`NoSpeechError` ("no speech found") when no 25 ms window rises above
    ``floor_db`` dB re full scale, or the clip is shorter than 0.1 s."""
    if audio.duration < 0.1:
        raise NoSpeechError(f"no speech found in {audio.source}: it lasts {audio.duration:.3f} s "
                            "(at least 0.1 s is needed)")
    win = int(0.025 * audio.rate)
    n = len(audio.samples) // win
    rms = np.sqrt(np.mean(audio.samples[:n * win].reshape(n, win) ** 2, axis=1))
    peak = 20 * np.log10(max(float(rms.max()), 1e-12))
    if peak < floor_db:
        raise NoSpeechError(f"no speech found in {audio.source}: its loudest 25 ms is {peak:.0f} dBFS, "
                            f"below {floor_db:.0f} dBFS (silence)")
