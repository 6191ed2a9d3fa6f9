"""Sensor noise of one grey-level scale on 8-bit images, drawn as integers.

A camera's ideal frame gets Gaussian noise of ``sigma`` grey levels and is rounded back to 8 bits:
``clip(round(image + sigma * z), 0, 255)`` with ``z ~ N(0, 1)``. The image is whole numbers, so
this equals ``clip(image + k, 0, 255)`` with ``k = round(sigma * z)``: an integer with

    P(k) = Phi((k + 1/2) / sigma) - Phi((k - 1/2) / sigma)

(the rounded Gaussian). :func:`add_rounded_gaussian` draws ``k`` directly, by the inverse of that
distribution's CDF on 32-bit uniform integers: a table on the top 16 bits settles all but the
few draws whose 16-bit bucket holds a step of the CDF, which are looked up exactly. The result
has the same distribution as the float path (to 2^-32 in probability) at 0.3-0.6x its CPU
(``lipgen bench --suite render``: ``frame_parts.noise_over_float``): one 32-bit draw and a table
look-up per value instead of a float32 normal draw, a multiply, an add, a rounding and a clip
over a float image. The draws differ from the float path's, so the frames' bytes do too.
"""

from __future__ import annotations

import functools
import math
import sys

import numpy as np

__all__ = ["rounded_gaussian_pmf", "rounded_gaussian", "add_rounded_gaussian"]

_TAIL = 9.0  # standard deviations kept: P(|z| > 9) is 2e-19, far below 2^-32
_STEP = np.int16(-32768)  # table entry: this 16-bit bucket holds a step of the CDF
_LITTLE = sys.byteorder == "little"
_RAW_OK = ("PCG64", "PCG64DXSM")  # bit generators whose 32-bit draws halve a 64-bit output as above


def _support(sigma: float) -> np.ndarray:
    K = int(math.ceil(_TAIL * sigma + 0.5))
    return np.arange(-K, K + 1)


def rounded_gaussian_pmf(sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """The distribution of ``round(sigma * z)``, ``z ~ N(0, 1)``.

    Returns
    -------
    k : (m,) int64
        Values, symmetric about 0, covering ``sigma * 9`` and more.
    p : (m,) float64
        Their probabilities (summing to 1 within 1e-15).
    """
    sigma = _check_sigma(sigma)
    k = _support(sigma)
    cdf = np.array([0.5 * math.erfc(-(x + 0.5) / (sigma * math.sqrt(2.0))) for x in k], float)
    return k, np.diff(np.concatenate([[0.0], cdf]))


def _check_sigma(sigma) -> float:
    s = float(sigma)
    if not math.isfinite(s) or s <= 0 or s > 1000:
        raise ValueError(f"sigma must be a finite number of grey levels in (0, 1000], got {sigma!r}")
    return s


@functools.lru_cache(maxsize=16)
def _tables(sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(edges (m-1,) uint64, values (m,) int16, bucket (65536,) int16)`` for 32-bit uniforms ``u``:
    ``k = values[searchsorted(edges, u, 'right')]``; ``bucket[u >> 16]`` is that k, or ``_STEP``."""
    k, p = rounded_gaussian_pmf(sigma)
    edges = np.round(np.cumsum(p)[:-1] * 2.0**32).astype(np.uint64)  # u < edges[j]: value index <= j
    values = k.astype(np.int16)
    start = np.arange(1 << 16, dtype=np.uint64) << np.uint64(16)
    first = np.searchsorted(edges, start, side="right")
    last = np.searchsorted(edges, start + np.uint64(0xFFFF), side="right")
    bucket = np.where(first == last, values[first], _STEP).astype(np.int16)
    return edges, values, bucket


def _uniform_u32(rng: np.random.Generator, n: int) -> np.ndarray:
    """``rng.integers(0, 2**32, size=n, dtype=np.uint32)``, the same values and the same state after.

    numpy draws each full-range 32-bit integer as the low, then the high half of the bit
    generator's next 64-bit output (keeping an unused high half for the next draw). With nothing
    kept, ``n`` even and a little-endian machine, that is ``random_raw(n // 2)`` seen as 32-bit
    halves, at about half the CPU (no call per value); otherwise ``integers`` itself.
    """
    bits = rng.bit_generator
    if n % 2 == 0 and _LITTLE and type(bits).__name__ in _RAW_OK and not bits.state.get("has_uint32", 1):
        return bits.random_raw(n // 2).view(np.uint32)
    return rng.integers(0, 1 << 32, size=n, dtype=np.uint32)


def rounded_gaussian(shape, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """Integers ``round(sigma * z)``, ``z ~ N(0, 1)`` independent, of the given ``shape`` (int16).

    Parameters
    ----------
    shape : tuple of int
    sigma : float
        Standard deviation of the Gaussian before rounding, grey levels; in (0, 1000].
    rng : numpy.random.Generator
        Source of the draws (one 32-bit integer per value).
    """
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    edges, values, bucket = _tables(_check_sigma(sigma))
    u = _uniform_u32(rng, int(np.prod(shape, dtype=np.int64)))
    k = bucket.take(u >> np.uint32(16))
    step = np.flatnonzero(k == _STEP)
    if step.size:
        k[step] = values[np.searchsorted(edges, u[step].astype(np.uint64), side="right")]
    return k.reshape(shape)


def add_rounded_gaussian(image: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """``clip(round(image + sigma * z), 0, 255)`` for a uint8 ``image`` (any shape), as uint8.

    ``sigma <= 0`` returns ``image`` itself. The draws are :func:`rounded_gaussian` 's.
    """
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise TypeError(f"image must be uint8, got {image.dtype} of shape {image.shape}")
    if sigma <= 0:
        return image
    out = image.astype(np.int16)
    out += rounded_gaussian(image.shape, sigma, rng)
    np.clip(out, 0, 255, out=out)
    return out.astype(np.uint8)
