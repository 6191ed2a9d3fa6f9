"""The mirror's front-surface ghost, estimated from chessboard images of one view.

A back-silvered mirror's glass reflects a few per cent of the light at its front surface, so the
mirror view holds a faint copy of itself shifted by a few pixels (the shift grows with the glass's
thickness and the angle of incidence). In linear light the view is ``I(p) + r I(p - delta)``.
The copy moves every corner of a board by about the same amount (``hard`` preset: r = 4 %,
7.3 px; about 0.09 px a board), which the per-board poses of the calibration cannot tell from the
lens's tangential terms. :func:`estimate_ghost` finds ``delta`` and ``r`` from all the boards of
a view together, with the corners: a search over whole-pixel shifts for the copy that best
explains what the plain X-junction fits leave, then one joint Gauss-Newton fit of the shift, the
strength and every corner (:mod:`lipgen.recon.cornerfit`'s model with the ghost term). Nothing
about the rig is read: the shift is what the images show.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter

from lipgen.recon.cornerfit import _model, _offsets, _prepare, _sample, _solve, _wave

__all__ = ["Ghost", "estimate_ghost", "MIN_STRENGTH", "MIN_SNR", "MIN_SHIFT_PX"]

MIN_STRENGTH = 0.01
"""Weakest ghost :attr:`Ghost.shown` accepts (``r``; uncoated glass gives about 0.05)."""
MIN_SNR = 50.0
"""Fewest standard errors a ghost's strength must be from zero for :attr:`Ghost.shown`."""
MIN_SHIFT_PX = 2.0
"""Smallest ghost shift :attr:`Ghost.shown` accepts, px (a nearer copy is not told apart from the blur)."""


@dataclass(frozen=True, eq=False)
class Ghost:
    """A view's ghost as estimated from its chessboard images.

    Attributes
    ----------
    shift : (2,) float
        ``delta``, px (column, row) in the view's image.
    strength : float
        ``r``: the copy's contrast over the image's own (linear light).
    snr : float
        ``r`` over its standard error (from the fit's residuals, pixels taken as independent,
        so an overestimate by the smoothing's correlation): how clearly the images show a ghost.
    corners : int
        Corners the joint fit used.
    """

    shift: np.ndarray
    strength: float
    snr: float
    corners: int

    @property
    def shown(self) -> bool:
        """Whether the images clearly show a ghost: a strength of at least :data:`MIN_STRENGTH` and
        :data:`MIN_SNR` standard errors, and a shift of at least :data:`MIN_SHIFT_PX`. Without a
        ghost the estimate is a spurious copy about 1.6 px away at 20-25 standard errors
        (``easy`` calibration frames and synthetic boards)."""
        return bool(self.strength >= MIN_STRENGTH and self.snr >= MIN_SNR
                    and float(np.linalg.norm(self.shift)) >= MIN_SHIFT_PX)

    @property
    def params(self) -> np.ndarray:
        """``(dx, dy, r)``, as :func:`lipgen.recon.cornerfit.fit_corners` takes it."""
        return np.array([self.shift[0], self.shift[1], self.strength])

    def to_dict(self) -> dict:
        """A JSON-ready dict."""
        return {"shift_px": [float(v) for v in self.shift], "strength": float(self.strength),
                "snr": float(self.snr), "corners": int(self.corners)}


def estimate_ghost(grays, corners, grid_shapes, max_shift: float = 12.0, reach: float = 0.7,
                   max_radius: float = 14.0, smooth: float = 0.5, search_corners: int = 100,
                   fit_corners: int = 800, iterations: int = 12) -> Ghost:
    """Estimate a view's ghost from its chessboard images, all together.

    Parameters
    ----------
    grays : sequence of (H, W) float
        The view's board images in linear light.
    corners : sequence of (rows_k * cols_k, 2) float
        Each image's corners (column, row), px, within a few tenths of a pixel (e.g. the plain
        fit's, :func:`lipgen.recon.cornerfit.fit_corners`).
    grid_shapes : sequence of (2,) int
        Each image's ``(rows, cols)`` of inner corners.
    max_shift : float
        Largest shift searched, px, in either coordinate.
    reach, max_radius, smooth : float
        As :func:`lipgen.recon.cornerfit.fit_corners`.
    search_corners, fit_corners : int
        At most this many corners (spread over the images) in the whole-pixel search, and in the
        joint fit. Only corners one step or more inside their grid are used: the model continues
        the squares beyond a board's last row, which its white margin does not.
    iterations : int
        Joint Gauss-Newton steps.

    Returns
    -------
    Ghost
    """
    grays, corners, grid_shapes = list(grays), list(corners), [tuple(int(v) for v in s) for s in grid_shapes]
    if not len(grays) == len(corners) == len(grid_shapes) or not grays:
        raise ValueError(f"grays, corners and grid_shapes must be equally long and not empty, got "
                         f"{len(grays)}, {len(corners)} and {len(grid_shapes)}")
    if not max_shift > 0:
        raise ValueError(f"max_shift must be positive (px), got {max_shift!r}")
    imgs, batches = [], []
    for k, (g, c, (rows, cols)) in enumerate(zip(grays, corners, grid_shapes, strict=True)):
        g, c = np.asarray(g, float), np.asarray(c, float)
        if g.ndim != 2:
            raise ValueError(f"grays[{k}] must be an (H, W) image, got shape {g.shape}")
        if c.shape != (rows * cols, 2):
            raise ValueError(f"corners[{k}] must be ({rows * cols}, 2) for a {rows}x{cols} grid, got shape "
                             f"{c.shape}")
        imgs.append(gaussian_filter(g, smooth, mode="nearest") if smooth > 0 else g)
        b = _prepare(c, (rows, cols), reach, max_radius)
        i, j = b["ij"].T
        keep = (i >= 1) & (i <= cols - 2) & (j >= 1) & (j <= rows - 2)
        batches.append({key: v[keep] for key, v in b.items()} | {"image": np.full(keep.sum(), k)})
    batch = {key: np.concatenate([b[key] for b in batches]) for key in batches[0]}
    if len(batch["theta"]) < 4:
        raise ValueError(f"too few interior corners to estimate a ghost: {len(batch['theta'])} (need 4)")
    image = batch.pop("image")
    theta, _ = _solve(imgs, image, batch, None, 6)  # the plain fit again, in these images (from its result)
    ok = np.isfinite(theta).all(1) & (np.abs(theta[:, 6]) > 1e-6)
    ok &= np.abs(theta[:, 4]) < 0.5 * batch["radius"]
    idx = np.flatnonzero(ok)
    sub = idx[np.linspace(0, len(idx) - 1, min(search_corners, len(idx))).round().astype(int)]
    start = _search(imgs, image[sub], theta[sub], batch["radius"][sub], batch["L"][sub], max_shift)
    use = idx[np.linspace(0, len(idx) - 1, min(fit_corners, len(idx))).round().astype(int)]
    part = {"theta": theta[use], "radius": batch["radius"][use], "L": batch["L"][use]}
    th, g = _solve(imgs, image[use], part, start, iterations, estimate=True)
    return Ghost(g[:2].copy(), float(g[2]), _snr(imgs, image[use], th, part, g), len(use))


def _search(imgs, image, theta, radius, L, max_shift) -> np.ndarray:
    """The whole-pixel shift (and its strength) whose copy best explains the plain fits' residuals.

    For each shift, the copy's template is made orthogonal to each corner's own Jacobian (what
    the corner's parameters would absorb); the shift with the largest positive explained sum of
    squares wins."""
    x, val, w = _sample(imgs, image, theta, radius, _offsets(radius))
    f, J, _ = _model(x, theta)
    Q = np.linalg.qr(J * w[..., None])[0]  # (n, P, 7)
    k, p = np.nonzero(w > 0)  # the pixels that count, flat
    res, w, Q, x = ((val - f) * w)[k, p], w[k, p], Q[k, p], x[k, p]
    c1, s1, c2, s2 = (fn(theta[k, col]) for col in (2, 3) for fn in (np.cos, np.sin))
    s = np.abs(theta[k, 4]) + 1e-9
    aw = theta[k, 6] * w
    u1, u2 = c1 * x[:, 0] + s1 * x[:, 1], c2 * x[:, 0] + s2 * x[:, 1]
    starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])  # each corner's first pixel (k is sorted)

    def score(dx, dy):
        t = aw * (_wave(u1 - (c1 * dx + s1 * dy), s, L[k, 0], False)[0]
                  * _wave(u2 - (c2 * dx + s2 * dy), s, L[k, 1], False)[0])
        proj = np.add.reduceat(Q * t[:, None], starts, axis=0)
        t = t - (Q * proj[k[starts].searchsorted(k)]).sum(1)
        num, den = float(res @ t), float(t @ t)
        return (num * num / den if num > 0 else 0.0), num / den

    # every second whole pixel, then every pixel round the three best
    m = int(np.floor(max_shift))
    coarse = [(dx, dy) for dy in range(-m, m + 1, 2) for dx in range(-m, m + 1, 2) if dx or dy]
    scores = {d: score(*d) for d in coarse}
    for d in sorted(scores, key=lambda d: -scores[d][0])[:3]:
        for dy in range(d[1] - 1, d[1] + 2):
            for dx in range(d[0] - 1, d[0] + 2):
                if (dx, dy) not in scores and (dx or dy) and max(abs(dx), abs(dy)) <= m:
                    scores[(dx, dy)] = score(dx, dy)
    d = max(scores, key=lambda d: scores[d][0])
    return np.array([d[0], d[1], max(scores[d][1], 0.0)], float)


def _snr(imgs, image, theta, part, g) -> float:
    """The ghost's strength over its standard error (the joint fit's Schur-reduced covariance)."""
    x, val, w = _sample(imgs, image, theta, part["radius"], _offsets(part["radius"]))
    f, J, Jg = _model(x, theta, part["L"], g, True)
    r = (val - f) * w
    Jw, Jgw = J * w[..., None], Jg * w[..., None]
    A = Jw.transpose(0, 2, 1) @ Jw
    B = Jw.transpose(0, 2, 1) @ Jgw
    S = np.einsum("npi,npj->ij", Jgw, Jgw) - np.einsum("nki,nkj->ij", B, np.linalg.pinv(A) @ B)
    dof = max(int((w > 0).sum()) - 7 * len(theta) - 3, 1)
    var = float((r ** 2).sum()) / dof
    cov = np.linalg.pinv(S) * var
    return float(g[2] / np.sqrt(max(cov[2, 2], 1e-30)))
