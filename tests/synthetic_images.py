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
    r = int(np.ceil(5 * sigma))
    for k, (u, v) in enumerate(uv):
        if (visible is not None and not visible[k]) or not np.isfinite(u + v):
            continue
        c0, r0 = max(int(u) - r, 0), max(int(v) - r, 0)
        c1, r1 = min(int(u) + r + 1, w), min(int(v) + r + 1, h)
        if c1 <= c0 or r1 <= r0:
            continue
        yy, xx = np.mgrid[r0:r1, c0:c1]
        img[r0:r1, c0:c1] -= depth * np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * sigma * sigma))
    return img


def frame(base, uv, rng, noise: float = 0.01, **kw) -> np.ndarray:
    """One uint8 frame: dots on ``base`` plus Gaussian pixel noise, quantised."""
    img = draw_dots(base, uv, **kw) + noise * rng.standard_normal(base.shape)
    return np.clip(np.round(img * 255), 0, 255).astype(np.uint8)


def swaying_views(cameras, points, n_frames: int, rng: np.random.Generator, shape=(120, 160)):
    """``points`` (P, 3) mm swaying together (a sine of 1.5 / 1.0 / 2.0 mm per axis) seen by
    ``cameras``: their uv (V, F, P, 2) and a textured background per camera (drawn from ``rng``)."""
    t = np.arange(n_frames)[:, None, None]
    marks = np.asarray(points)[None] + np.array([1.5, 1.0, 2.0]) * np.sin(0.3 * t)
    uv = np.stack([np.stack([c.project(m) for m in marks]) for c in cameras])
    return uv, [background(shape, rng) for _ in cameras]


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


def render_board(camera, object_size, square, pose, supersample: int = 3, rng=None,
                 noise: float = 0.0) -> np.ndarray:
    """Ray-cast a planar chessboard seen by a :class:`~lipgen.rig.pinhole.PinholeCamera`.

    ``object_size`` is (inner_cols, inner_rows); inner corner (i, j) is at (i, j, 0) * square in
    the board frame, and ``pose = (A, b)`` places it in the world (X = A p + b). A white border
    of two squares surrounds the board; the rest is mid grey. Returns a (h, w) float image.
    """
    cols, rows = object_size
    A, b = pose
    h, w = camera.height, camera.width
    img = np.full((h, w), 0.45)
    # Render only the board's bounding box (plus a margin), with sub-pixel supersampling.
    outline = np.array([[-3, -3, 0], [cols + 2, -3, 0], [-3, rows + 2, 0], [cols + 2, rows + 2, 0]],
                       float) * square
    uv = camera.project(outline @ A.T + b)
    u0, v0 = np.clip(np.floor(uv.min(0)).astype(int) - 2, 0, [w - 1, h - 1])
    u1, v1 = np.clip(np.ceil(uv.max(0)).astype(int) + 2, 0, [w - 1, h - 1])
    sub = (np.arange(supersample) + 0.5) / supersample - 0.5
    uu, vv = np.meshgrid(np.arange(u0, u1 + 1), np.arange(v0, v1 + 1))
    shape = uu.shape + (supersample, supersample)
    su = np.broadcast_to(uu[..., None, None] + sub[:, None], shape).ravel()
    sv = np.broadcast_to(vv[..., None, None] + sub[None, :], shape).ravel()
    o, d = camera.rays(np.column_stack([su, sv]))
    n = A[:, 2]
    s = ((b - o) @ n) / (d @ n)
    p = (o + s[:, None] * d - b) @ A
    ix, iy = np.floor(p[:, 0] / square), np.floor(p[:, 1] / square)
    on_board = (ix >= -1) & (ix <= cols - 1) & (iy >= -1) & (iy <= rows - 1)
    border = (ix >= -3) & (ix <= cols + 1) & (iy >= -3) & (iy <= rows + 1)
    val = np.where(border, 0.92, 0.45)
    val = np.where(on_board & ((ix + iy) % 2 == 0), 0.08, val)
    val = val.reshape(uu.shape + (supersample * supersample,)).mean(-1)
    img[v0:v1 + 1, u0:u1 + 1] = val
    if noise and rng is not None:
        img = img + noise * rng.standard_normal(img.shape)
    return np.clip(img, 0, 1)


def render_marker_frames(rig, points, rng, sigma: float = 1.3, depth: float = 0.35, noise: float = 0.01,
                         hidden=None):
    """Raw camera-mirror frames of dark dots at world ``points (F, P, 3)`` on textured skin.

    Each view gets its own fixed background; dots outside a view (or behind the mirror) or
    flagged in ``hidden (F, P)`` are not drawn. Returns a list of (H, W) uint8 frames.
    """
    backgrounds = [background((cam.height, cam.width), rng) for cam in rig.views]
    frames = []
    for f, X in enumerate(points):
        uv, _, inside = rig.project(X)
        views = []
        for v, base in enumerate(backgrounds):
            show = inside[v] if hidden is None else inside[v] & ~hidden[f]
            views.append(frame(base, uv[v], rng, noise=noise, sigma=sigma, depth=depth, visible=show))
        frames.append(rig.compose(*views))
    return frames
