"""Synthetic test images: dark Gaussian ink dots on a textured, shaded background, with noise.

The dot centres are known exactly, so detectors and trackers can be scored against them.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage


def background(shape, rng: np.random.Generator, texture: float = 0.08) -> np.ndarray:
    """A smooth shading gradient plus a blotchy skin-like texture, in [0, 1]."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w]
    shade = 0.65 + 0.15 * (xx / w) - 0.1 * (yy / h)
    blotch = ndimage.gaussian_filter(rng.standard_normal(shape), 6.0)
    blotch *= texture / (blotch.std() + 1e-12)
    fine = ndimage.gaussian_filter(rng.standard_normal(shape), 1.0)
    fine *= 0.25 * texture / (fine.std() + 1e-12)
    return shade + blotch + fine


def draw_dots(base: np.ndarray, uv: np.ndarray, sigma: float = 1.5, depth: float = 0.35,
              visible=None) -> np.ndarray:
    """Subtract Gaussian dots of peak ``depth`` centred at ``uv (k, 2)`` (column, row)."""
    img = base.copy()
    h, w = img.shape
    yy, xx = np.mgrid[0:h, 0:w]
    for k, (u, v) in enumerate(uv):
        if visible is not None and not visible[k]:
            continue
        img -= depth * np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * sigma * sigma))
    return img


def frame(base, uv, rng, noise: float = 0.01, **kw) -> np.ndarray:
    """One uint8 frame: dots on ``base`` plus Gaussian pixel noise, quantised."""
    img = draw_dots(base, uv, **kw) + noise * rng.standard_normal(base.shape)
    return np.clip(np.round(img * 255), 0, 255).astype(np.uint8)


def marker_paths(n_frames: int, n_markers: int, rng: np.random.Generator, shape=(120, 160),
                 spacing: float = 14.0, amplitude: float = 6.0, own: float = 1.5) -> np.ndarray:
    """Known smooth paths (F, P, 2): a jittered grid moving together (sinusoidal translation of
    ``amplitude`` px) plus each marker's own sinusoid of ``own`` px, so dots never touch."""
    h, w = shape
    cols = int(np.ceil(np.sqrt(n_markers * w / h)))
    grid = np.array([(c, r) for r in range(n_markers) for c in range(cols)][:n_markers], float)
    start = grid * spacing + np.array([w, h]) / 2 - grid.mean(0) * spacing
    start += rng.uniform(-1, 1, start.shape)
    t = np.arange(n_frames)[:, None, None]
    phase = rng.uniform(0, 2 * np.pi, (1, n_markers, 2))
    freq = rng.uniform(0.05, 0.12, (1, n_markers, 2))
    common = amplitude * np.sin(np.array([0.15, 0.11]) * t)
    return start[None] + common + own * (np.sin(freq * t + phase) - np.sin(phase))
