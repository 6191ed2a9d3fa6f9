"""Chessboard corners to sub-pixel by fitting a blurred X-junction model (least squares).

Near an inner corner, a chessboard image is two straight edges crossing at the corner, blurred
(defocus, demosaicing, the pixel's area) and seen through a tone curve. The model here is

    I(p) = m + a * E(n1 . (p - c) / s) * E(n2 . (p - c) / s),     E(t) = erf(t / sqrt(2)),

with the corner ``c``, the edges' unit normals ``n1``, ``n2`` (angles ``phi1``, ``phi2``), the blur
scale ``s`` (px), the mean ``m`` and the contrast ``a``: exact for perpendicular edges under a
Gaussian blur, and close otherwise. It is fitted to every pixel in a disc round the corner,
all corners at once (Gauss-Newton with Levenberg damping, analytic derivatives).

Why the corner comes out unbiased even where the model is only close (a disc blur, a skewed
corner, the sRGB curve, JPEG's and Bayer's smoothing): two crossing straight edges, however
blurred by a symmetric kernel and whatever the tone curve, give an image symmetric under a
half turn about the crossing, and so does the model; the fit on a disc centred on the corner
therefore puts ``c`` on the crossing. What the fit gains over OpenCV's ``cornerSubPix``
(gradients orthogonal to ``p - c`` in a square window of about half a square) is that every
pixel's value enters, weighted by how much it says about ``c``, over a disc reaching most of
the way to the neighbouring corners (``reach`` times their distance): about twice the edge
length of the usual window, and the noise, the aliasing of the rendered edges and the JPEG
blocks average over it. Measured on rendered ``hard`` calibration frames in
:mod:`lipgen.recon.chessboard`.

A mirror's glass adds a faint copy of the whole view, shifted (its front-surface ghost). In linear
light the image is then ``I(p) + r I(p - delta)``; ``ghost=(dx, dy, r)`` adds to the model the
copy of the local board, ``r * a * W1 * W2`` at ``p - delta``, where ``W1``, ``W2`` are the
blurred square waves of the board's two families of lines (five edges each, spaced as the
neighbouring corners), so that the copy is right however far the shift reaches across the
squares. The shift and strength are estimated from all boards of a view together
(:func:`lipgen.recon.ghost.estimate_ghost`).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter
from scipy.special import erf as _erf_everywhere

__all__ = ["fit_corners", "ghost_params"]

_SQRT2 = np.sqrt(2.0)
_G = np.sqrt(2.0 / np.pi)
_WAVE = (-2, -1, 0, 1, 2)  # the edges of a square wave, in line spacings
_ERF_ONE = 6.0  # scipy's float64 erf(z) is exactly +-1.0 for |z| >= 5.93 (checked densely up to 50)


def _erf(z):
    """scipy's ``erf``, the same values, evaluated only where it is not exactly +-1: most pixels
    of a corner's disc lie far from most of the edges the model places there."""
    z = np.asarray(z, dtype=np.float64)
    out = np.sign(z)  # NaN stays NaN, as erf(NaN)
    near = np.abs(z) < _ERF_ONE
    out[near] = _erf_everywhere(z[near])
    return out


def ghost_params(ghost, message: str) -> np.ndarray:
    """(3,) float: ``ghost`` as (dx, dy, r) with finite values and 0 <= r < 1, else ValueError(message).

    Parameters
    ----------
    ghost : array-like
        The ghost's shift (px) and strength.
    message : str
        The error's opening words (the caller's allowed values).
    """
    g = np.asarray(ghost, float) if not isinstance(ghost, str) else np.array([])
    if g.shape != (3,) or not np.isfinite(g).all() or not 0 <= g[2] < 1:
        raise ValueError(f"{message}, got {ghost if isinstance(ghost, str) else g!r} of shape {g.shape}")
    return g


def fit_corners(gray, corners, grid_shape, reach: float = 0.7, max_radius: float = 14.0,
                iterations: int = 12, max_move: float = 1.5, smooth: float = 0.5,
                ghost=None) -> tuple[np.ndarray, np.ndarray]:
    """Refine chessboard corners by fitting the blurred X-junction model.

    Parameters
    ----------
    gray : (H, W) float
        The image (any linear or tone-mapped scale; the model's mean and contrast are fitted).
        With ``ghost``, linear light (the ghost adds in linear light).
    corners : (rows * cols, 2) float
        Starting corners (column, row), px, row by row in a ``grid_shape`` grid, within about a
        pixel of the truth (e.g. ``cornerSubPix``'s).
    grid_shape : (2,) int
        ``(rows, cols)`` of inner corners: the neighbours give each corner's edge directions and
        the radius of its disc.
    reach : float
        Disc radius as a fraction of the distance to the nearest neighbouring corner.
    max_radius : float
        Largest disc radius, px.
    iterations : int
        Gauss-Newton steps (the disc is re-centred on the current corner before each).
    smooth : float
        Standard deviation (px) of a Gaussian the image is smoothed with first (0: none). A sharp
        edge sampled by pixel areas is a ramp, not the model's erf, and its fitted position then
        locks toward the pixel grid (synthetic boards without blur: 0.028 px RMS, 0.015 px mean);
        0.5 px makes the profile erf-like (0.008 px) and costs nothing on blurred edges.
    max_move : float
        A corner whose fit moves farther than this from its start (px), leaves the image, or does
        not fit (a contrast of the wrong sign, a blur over half the radius) keeps its start.
    ghost : (3,) float or None
        A known ghost ``(dx, dy, r)``: the image holds ``r`` times a copy of itself shifted by
        ``(dx, dy)`` px (see the module's docstring); None: no ghost.

    Returns
    -------
    corners : (rows * cols, 2) float
        Refined corners.
    fitted : (rows * cols,) bool
        Which corners were refined (the others are their starts).
    """
    g = np.asarray(gray, float)
    c0 = np.asarray(corners, float)
    rows, cols = (int(v) for v in grid_shape)
    if g.ndim != 2:
        raise ValueError(f"gray must be an (H, W) image, got shape {g.shape}")
    if c0.shape != (rows * cols, 2):
        raise ValueError(f"corners must be ({rows * cols}, 2) for a {rows}x{cols} grid, got shape {c0.shape}")
    if ghost is not None:
        ghost = ghost_params(ghost, "ghost must be (dx, dy, r) with finite values and 0 <= r < 1")
    if smooth > 0:
        g = gaussian_filter(g, smooth, mode="nearest")
    batch = _prepare(c0, (rows, cols), reach, max_radius)
    theta, _ = _solve([g], np.zeros(len(c0), int), batch, ghost, iterations)
    return _accept(theta, c0, batch["radius"], g.shape, max_move)


def _prepare(c0: np.ndarray, grid_shape, reach: float, max_radius: float) -> dict:
    """Per corner: the starting parameters, the disc radius, the signed line spacings, the grid index."""
    rows, cols = grid_shape
    grid = c0.reshape(rows, cols, 2)
    # edge directions from the neighbours (central differences, one-sided at the border)
    du = np.gradient(grid, axis=1).reshape(-1, 2)  # along a row of corners
    dv = np.gradient(grid, axis=0).reshape(-1, 2)  # along a column
    near = np.full((rows, cols), np.inf)
    for axis in (0, 1):
        d = np.linalg.norm(np.diff(grid, axis=axis), axis=-1)
        lo = [slice(None)] * 2
        hi = [slice(None)] * 2
        lo[axis], hi[axis] = slice(None, -1), slice(1, None)
        near[tuple(lo)] = np.minimum(near[tuple(lo)], d)
        near[tuple(hi)] = np.minimum(near[tuple(hi)], d)
    radius = np.clip(reach * near.ravel(), 2.0, max_radius)
    # the edge along u has its normal perpendicular to u. Contiguous inputs: on a strided view numpy
    # (1.26, AVX-512) may take libm's arctan2 instead of its vector one, 1 ulp apart, depending on
    # where the output is allocated (tests/test_dot_fit_layout.py)
    phi1 = np.arctan2(np.ascontiguousarray(du[:, 0]), -du[:, 1])
    phi2 = np.arctan2(np.ascontiguousarray(dv[:, 0]), -dv[:, 1])
    n = len(c0)
    # spacing of each family of lines along its normal: the next row (column) of corners
    L = np.column_stack([np.cos(phi1) * dv[:, 0] + np.sin(phi1) * dv[:, 1],
                         np.cos(phi2) * du[:, 0] + np.sin(phi2) * du[:, 1]])
    j, i = np.mgrid[0:rows, 0:cols]
    theta = np.column_stack([c0, phi1, phi2, np.ones(n), np.zeros(n), np.zeros(n)])  # c, phi1, phi2, s, m, a
    return {"theta": theta, "radius": radius, "L": L, "ij": np.column_stack([i.ravel(), j.ravel()])}


def _sample(grays, image, theta, radius, off):
    """Pixels round each corner's current centre: offsets ``x`` (n, P, 2), values (n, P), weights (n, P)."""
    centre = np.round(theta[:, :2])
    pix = centre[:, None, :] + off[None]  # (n, P, 2)
    val = np.empty(pix.shape[:2])
    inside = np.empty(pix.shape[:2], bool)
    for k, g in enumerate(grays):
        sel = image == k
        if not sel.any():
            continue
        H, W = g.shape
        p = pix[sel]
        inside[sel] = (p[..., 0] >= 0) & (p[..., 0] < W) & (p[..., 1] >= 0) & (p[..., 1] < H)
        val[sel] = g[np.clip(p[..., 1].astype(int), 0, H - 1), np.clip(p[..., 0].astype(int), 0, W - 1)]
    x = pix - theta[:, None, :2]
    # a soft disc edge (1 px), so that the fit moves smoothly as the disc is re-centred
    w = np.clip(radius[:, None] + 0.5 - np.linalg.norm(x, axis=-1), 0.0, 1.0) * inside
    return x, val, w


def _solve(grays, image, batch, ghost, iterations, estimate: bool = False):
    """Damped Gauss-Newton on the corners of ``batch`` (in images ``grays[image[i]]``).

    With ``estimate``, the ghost ``(dx, dy, r)`` is fitted too, jointly with every corner (the
    normal equations reduced to the ghost's three unknowns by the Schur complement, one damping
    for all); otherwise each corner is damped and accepted on its own. Returns the parameters
    (n, 7) and the ghost (3,) or None."""
    theta = batch["theta"].copy()
    radius, L = batch["radius"], batch["L"]
    n = len(theta)
    off = _offsets(radius)  # (P, 2)
    lam = np.full(n, 1e-3)
    first = True
    for _ in range(iterations):
        x, val, w = _sample(grays, image, theta, radius, off)
        if first:  # mean and contrast by linear least squares on the starting edges
            theta[:, 5:7] = _linear_fit(_shape(x, theta, L, ghost), val, w)
            first = False
        f, J, Jg = _model(x, theta, L, ghost, estimate)
        r = (val - f) * w
        Jw = J * w[..., None]
        JwT = Jw.transpose(0, 2, 1)
        A = JwT @ Jw
        b = (JwT @ r[..., None])[..., 0]
        cost = (r ** 2).sum(1)
        A = A + lam[:, None, None] * np.einsum("nii->ni", A)[:, :, None] * np.eye(7)
        if estimate:
            Jgw = Jg * w[..., None]
            B = JwT @ Jgw  # (n, 7, 3)
            C = np.einsum("npi,npj->ij", Jgw, Jgw)
            bg = np.einsum("npi,np->i", Jgw, r)
            AiB = _solve_stack(A, B)
            Aib = _solve_stack(A, b[..., None])[..., 0]
            S = C * (1 + lam[0] * np.eye(3)) - np.einsum("nki,nkj->ij", B, AiB)
            dg = np.linalg.solve(S, bg - np.einsum("nki,nk->i", B, Aib))
            step = Aib - AiB @ dg
            trial_g = ghost + dg
            trial = theta + step
            cost_t = (((val - _value(x, trial, L, trial_g)) * w) ** 2).sum(1)
            if cost_t.sum() < cost.sum():
                theta, ghost, lam = trial, trial_g, lam * 0.3
                if np.abs(dg[:2]).max() < 1e-3 and np.abs(step[:, :2]).max() < 2e-3:
                    break
            else:
                lam = lam * 10.0
            continue
        step = _solve_stack(A, b[..., None])[..., 0]
        trial = theta + step
        cost_t = (((val - _value(x, trial, L, ghost)) * w) ** 2).sum(1)  # the model's values, no Jacobian
        better = cost_t < cost
        theta = np.where(better[:, None], trial, theta)
        lam = np.where(better, lam * 0.3, lam * 10.0)
        if (np.abs(step[:, :2]) < 1e-4).all() and better.all():  # converged: a step of 1e-4 px
            break
    return theta, ghost


def _solve_stack(A, B):
    """``A^-1 B`` for a stack of systems; least squares where one is singular (a corner without edges)."""
    try:
        return np.linalg.solve(A, B)
    except np.linalg.LinAlgError:
        return np.stack([np.linalg.lstsq(Ai, Bi, rcond=None)[0] for Ai, Bi in zip(A, B, strict=True)])


def _accept(theta, c0, radius, shape, max_move):
    """The fitted corners where the fit is sound, else the starts; and which were fitted."""
    H, W = shape
    moved = np.linalg.norm(theta[:, :2] - c0, axis=1)
    s = np.abs(theta[:, 4])
    ok = np.isfinite(theta).all(1) & (moved <= max_move) & (s < 0.5 * radius)
    ok &= (theta[:, 0] >= 0) & (theta[:, 0] <= W - 1) & (theta[:, 1] >= 0) & (theta[:, 1] <= H - 1)
    ok &= np.abs(theta[:, 6]) > 1e-6
    return np.where(ok[:, None], theta[:, :2], c0), ok


def _wave(t, s, L, deriv: bool = True):
    """A blurred square wave of edges at ``k L`` (k in -2..2), sign +1 just above 0: values, and
    derivatives in ``t`` and ``s`` (None without ``deriv``)."""
    W = np.zeros_like(t)
    dt, ds = (np.zeros_like(t), np.zeros_like(t)) if deriv else (None, None)
    for k in _WAVE:
        u = (t - k * L) / s
        sign = -1.0 if k % 2 else 1.0
        W += sign * _erf(u / _SQRT2)
        if not deriv:
            continue
        G = sign * _G / s * np.exp(-0.5 * u * u)
        dt += G
        ds -= G * u
    return W, dt, ds


def _offsets(radius) -> np.ndarray:
    """(P, 2) float: the whole-pixel offsets of a square reaching past the largest ``radius``."""
    R = int(np.ceil(radius.max())) + 1
    oy, ox = np.mgrid[-R:R + 1, -R:R + 1]
    return np.column_stack([ox.ravel(), oy.ravel()]).astype(float)


def _ghost_geometry(x, theta, ghost):
    """The ghost's line coordinates ``t1``, ``t2`` (n, P), and pieces for its derivatives."""
    c1, s1 = np.cos(theta[:, 2])[:, None], np.sin(theta[:, 2])[:, None]
    c2, s2 = np.cos(theta[:, 3])[:, None], np.sin(theta[:, 3])[:, None]
    xg = x - ghost[:2]
    return c1 * xg[..., 0] + s1 * xg[..., 1], c2 * xg[..., 0] + s2 * xg[..., 1], (c1, s1, c2, s2, xg)


def _shape(x, theta, L, ghost):
    """The model's shape without mean and contrast: ``E1 E2`` plus the ghost ``r W1 W2``."""
    EE = _parts(x, theta)[0]
    if ghost is None:
        return EE
    t1, t2, _ = _ghost_geometry(x, theta, ghost)
    s = np.abs(theta[:, 4])[:, None] + 1e-9
    return EE + ghost[2] * _wave(t1, s, L[:, :1], False)[0] * _wave(t2, s, L[:, 1:], False)[0]


def _value(x, theta, L, ghost):
    """Model values (n, P)."""
    return theta[:, 5:6] + theta[:, 6:7] * _shape(x, theta, L, ghost)


def _parts(x, theta):
    """Per corner and pixel: E1 * E2, and the pieces of its derivatives."""
    c1, s1 = np.cos(theta[:, 2])[:, None], np.sin(theta[:, 2])[:, None]
    c2, s2 = np.cos(theta[:, 3])[:, None], np.sin(theta[:, 3])[:, None]
    s = np.abs(theta[:, 4])[:, None] + 1e-9
    d1 = c1 * x[..., 0] + s1 * x[..., 1]
    d2 = c2 * x[..., 0] + s2 * x[..., 1]
    E1, E2 = _erf(d1 / (_SQRT2 * s)), _erf(d2 / (_SQRT2 * s))
    return E1 * E2, (c1, s1, c2, s2, s, d1, d2, E1, E2)


def _model(x, theta, L=None, ghost=None, estimate=False):
    """Model values (n, P), the Jacobian (n, P, 7) in (cx, cy, phi1, phi2, s, m, a), and with
    ``estimate`` the Jacobian (n, P, 3) in the ghost's (dx, dy, r) (else None)."""
    EE, (c1, s1, c2, s2, s, d1, d2, E1, E2) = _parts(x, theta)
    m, a = theta[:, 5:6], theta[:, 6:7]
    G1 = _G / s * np.exp(-0.5 * (d1 / s) ** 2)
    G2 = _G / s * np.exp(-0.5 * (d2 / s) ** 2)
    t1 = a * G1 * E2
    t2 = a * E1 * G2
    J = np.stack([
        -(t1 * c1 + t2 * c2),
        -(t1 * s1 + t2 * s2),
        t1 * (-s1 * x[..., 0] + c1 * x[..., 1]),
        t2 * (-s2 * x[..., 0] + c2 * x[..., 1]),
        -(t1 * d1 + t2 * d2) / s,
        np.ones_like(EE),
        EE,
    ], -1)
    f = m + a * EE
    if ghost is None:
        return f, J, None
    u1, u2, (c1, s1, c2, s2, xg) = _ghost_geometry(x, theta, ghost)
    W1, dW1, sW1 = _wave(u1, s, L[:, :1])
    W2, dW2, sW2 = _wave(u2, s, L[:, 1:])
    r = ghost[2]
    WW = W1 * W2
    g1, g2 = a * dW1 * W2, a * W1 * dW2  # a times the derivatives along each normal
    dx, dy = -(g1 * c1 + g2 * c2), -(g1 * s1 + g2 * s2)
    J = J + r * np.stack([
        dx, dy,
        g1 * (-s1 * xg[..., 0] + c1 * xg[..., 1]),
        g2 * (-s2 * xg[..., 0] + c2 * xg[..., 1]),
        a * (sW1 * W2 + W1 * sW2),
        np.zeros_like(WW),
        WW,
    ], -1)
    Jg = np.stack([r * dx, r * dy, a * WW], -1) if estimate else None
    return f + a * r * WW, J, Jg


def _linear_fit(E, val, w):
    """Per corner (m, a) minimising sum w^2 (val - m - a E)^2."""
    w2 = w ** 2
    S0, S1, S2 = w2.sum(1), (w2 * E).sum(1), (w2 * E * E).sum(1)
    T0, T1 = (w2 * val).sum(1), (w2 * val * E).sum(1)
    det = S0 * S2 - S1 ** 2
    det = np.where(np.abs(det) < 1e-12, 1e-12, det)
    return np.column_stack([(S2 * T0 - S1 * T1) / det, (S0 * T1 - S1 * T0) / det])
