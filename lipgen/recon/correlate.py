"""Template matching for the marker tracker: normalised cross-correlation and its sub-pixel peak.

Every ink dot looks like every other, so the tracker correlates each marker's own template near
its predicted position (:func:`correlate_near`) and breaks ties by distance to the prediction.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import fftconvolve

__all__ = ["normalized_correlation", "correlate_near", "patch_around", "search_box"]


def normalized_correlation(search: np.ndarray, template: np.ndarray) -> np.ndarray:
    """Zero-mean normalised cross-correlation of ``template`` at every placement in ``search``.

    Parameters
    ----------
    search : (H, W) float
    template : (h, w) float, h <= H, w <= W

    Returns
    -------
    (H - h + 1, W - w + 1) float in [-1, 1]
        Entry (i, j) compares ``template`` with ``search[i:i+h, j:j+w]``; 0 where either is flat.
    """
    t = template - template.mean()
    tn = np.sqrt((t * t).sum())
    h, w = template.shape
    num = fftconvolve(search, t[::-1, ::-1], mode="valid")   # sum((win - mean) t) = sum(win t)
    # Window sums of the search and its square from integral images.
    def box(a):
        c = np.pad(a, ((1, 0), (1, 0))).cumsum(0).cumsum(1)
        return c[h:, w:] - c[:-h, w:] - c[h:, :-w] + c[:-h, :-w]
    mean = box(search) / t.size
    var = box(search * search) - mean * mean * t.size
    den = np.sqrt(np.maximum(var, 0.0)) * tn
    return np.where(den > 1e-9 * max(tn, 1e-300), num / np.maximum(den, 1e-300), 0.0)


def _parabola_offset(left: float, mid: float, right: float) -> float:
    den = left - 2.0 * mid + right
    return 0.0 if den >= 0 else float(np.clip(0.5 * (left - right) / den, -0.5, 0.5))


def patch_around(gray: np.ndarray, center: np.ndarray, radius: int) -> np.ndarray:
    """Square patch of side ``2 * radius + 1`` around the rounded centre, edge-padded.

    Parameters
    ----------
    gray : (H, W) float
    center : (2,) float
        (u, v) pixels.
    radius : int

    Returns
    -------
    (2 * radius + 1, 2 * radius + 1) float
    """
    c, r = np.round(center).astype(np.int64)
    h, w = gray.shape
    rows = np.clip(np.arange(r - radius, r + radius + 1), 0, h - 1)
    cols = np.clip(np.arange(c - radius, c + radius + 1), 0, w - 1)
    return gray[np.ix_(rows, cols)]


def correlate_near(gray: np.ndarray, template: np.ndarray, center: np.ndarray, radius: int,
               penalty: float) -> tuple[np.ndarray, float]:
    """Best placement of ``template`` within ``radius`` of ``center``.

    Every ink dot looks like every other, so the peak is chosen on the correlation minus
    ``penalty * (distance / radius)^2``: of two equally good matches, the one nearer the
    prediction wins.

    Parameters
    ----------
    gray : (H, W) float
    template : (h, h) float, h odd
    center : (2,) float
        The prediction (u, v), pixels.
    radius : int
        Search radius, pixels.
    penalty : float
        Weight of the distance prior.

    Returns
    -------
    uv : (2,) float
        The sub-pixel peak (parabola fit per axis).
    score : float
        The plain correlation at the peak, in [-1, 1].
    """
    t_rad = template.shape[0] // 2
    search = patch_around(gray, center, radius + t_rad)
    ncc = normalized_correlation(search, template)
    off = (np.arange(ncc.shape[0]) - radius) / max(radius, 1)
    prior = penalty * (off[:, None] ** 2 + off[None, :] ** 2)
    i, j = np.unravel_index(int(np.argmax(ncc - prior)), ncc.shape)
    di = _parabola_offset(ncc[i - 1, j], ncc[i, j], ncc[i + 1, j]) if 0 < i < ncc.shape[0] - 1 else 0.0
    dj = _parabola_offset(ncc[i, j - 1], ncc[i, j], ncc[i, j + 1]) if 0 < j < ncc.shape[1] - 1 else 0.0
    base = np.round(center)
    uv = np.array([base[0] - radius + j + dj, base[1] - radius + i + di])
    return uv, float(ncc[i, j])


def search_box(points: np.ndarray, margin: float,
               shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray] | None:
    """The image region searched around some points: their bounding box grown by ``margin``.

    Parameters
    ----------
    points : (K, 2) float
        Pixel positions (x, y), finite.
    margin : float
        Pixels added on every side.
    shape : (H, W) int
        The image's shape; the box is clipped to it.

    Returns
    -------
    (lo, hi) : two (2,) int, or None
        Corners (x, y; ``hi`` exclusive); None when the box is under 8 px on a side.
    """
    h, w = shape
    lo = np.maximum(np.floor(points.min(0) - margin).astype(int), 0)
    hi = np.minimum(np.ceil(points.max(0) + margin).astype(int) + 1, [w, h])
    return None if np.any(hi - lo < 8) else (lo, hi)
