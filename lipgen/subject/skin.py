"""Procedural skin and lip textures, one set per subject (seeded).

The textures are planar maps of the model frame's (x, y) at rest (``uv_of``), multiplied with the
materials' base colours: the skin gets blotchy colour variation a few millimetres across and pores
(dark specks of 0.1-0.25 mm, about 2 per mm²); the vermilion gets the vertical lip lines (furrows
about a millimetre apart, slightly wavy) over its own colour variation. ``skin_tone`` draws the
subject's skin colour from a range of tones (light to brown).
"""

from __future__ import annotations

import numpy as np

__all__ = ["UV_BOX", "uv_of", "skin_tone", "skin_texture", "lip_texture"]

UV_BOX = np.array([[-100.0, -120.0], [100.0, 140.0]])
"""Model-frame (x, y) box, mm, that the textures cover (corners: u, v = 0 and 1)."""
_PX = 1024

_LIGHT = np.array([0.90, 0.70, 0.58])
_DARK = np.array([0.58, 0.40, 0.31])


def uv_of(vertices: np.ndarray) -> np.ndarray:
    """(n, 2) texture coordinates of rest vertices (model frame, mm)."""
    lo, hi = UV_BOX
    return np.clip((np.asarray(vertices, float)[:, :2] - lo) / (hi - lo), 0.0, 1.0)


def skin_tone(rng: np.random.Generator) -> tuple[float, float, float]:
    """A skin colour (sRGB) between a light and a brown tone."""
    t = rng.uniform(0.0, 1.0)
    return tuple(float(x) for x in (1 - t) * _LIGHT + t * _DARK)


def _smooth_noise(rng, sigma_mm: float, shape=(_PX, _PX)) -> np.ndarray:
    from scipy.ndimage import gaussian_filter

    mm_per_px = (UV_BOX[1] - UV_BOX[0]).max() / _PX
    n = gaussian_filter(rng.standard_normal(shape), sigma_mm / mm_per_px, mode="wrap")
    return n / max(n.std(), 1e-12)


def _to_uint8(rgb: np.ndarray) -> np.ndarray:
    return np.clip(np.round(rgb * 255), 0, 255).astype(np.uint8)


def skin_texture(rng: np.random.Generator, strength: float = 1.0) -> np.ndarray:
    """(1024, 1024, 3) uint8 multiplier of the skin colour: blotches and pores."""
    blotch = 0.05 * _smooth_noise(rng, 6.0)[..., None] * np.array([1.0, 1.3, 1.3])  # redder patches
    fine = 0.02 * _smooth_noise(rng, 0.4)[..., None]
    pores = np.zeros((_PX, _PX))
    k = int(2.0 * ((UV_BOX[1] - UV_BOX[0]).prod()) * 0.25)  # ~2 per mm² on the ~quarter that is skin
    ij = rng.integers(0, _PX, (k, 2))
    np.add.at(pores, (ij[:, 0], ij[:, 1]), rng.uniform(0.08, 0.2, k))
    tex = 0.9 * (1 + strength * (blotch + fine - np.minimum(pores, 0.3)[..., None]))
    return _to_uint8(tex)


def lip_texture(rng: np.random.Generator, strength: float = 1.0) -> np.ndarray:
    """(1024, 1024, 3) uint8 multiplier of the vermilion colour: vertical lip lines and variation."""
    mm_per_px = (UV_BOX[1] - UV_BOX[0]) / _PX
    x = np.arange(_PX) * mm_per_px[0]
    y = np.arange(_PX) * mm_per_px[1]
    wobble = 0.6 * np.sin(2 * np.pi * y[:, None] / rng.uniform(6, 10) + rng.uniform(0, 2 * np.pi))
    phase = x[None, :] + wobble + 0.3 * _smooth_noise(rng, 2.0)
    spacing = rng.uniform(0.8, 1.3)
    lines = np.clip(np.cos(2 * np.pi * phase / spacing), 0.75, 1.0)  # narrow furrows between ridges
    lines = (lines - 0.75) / 0.25
    depth = 0.10 * (0.6 + 0.4 * _smooth_noise(rng, 3.0).clip(-1.5, 1.5) / 1.5)
    tex = 0.9 * (1 + strength * (0.04 * _smooth_noise(rng, 4.0) - depth * lines))[..., None]
    return _to_uint8(np.broadcast_to(tex, (_PX, _PX, 3)))
