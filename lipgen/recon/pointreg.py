"""Registering a 2-D marker layout to detected dots (similarity transform, one-to-one matches).

Used to initialise tracking from the first frame (replacing the thesis's GUI) and, every frame,
to catch sudden global jumps of the face.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from lipgen._validate import as_float_array

__all__ = ["assign", "similarity_2d", "register_points", "register_nonrigid", "match_to_expected",
           "layout_spacing"]

_BIG = 1e12
# Trimming (robust=True): a match is an outlier when its residual exceeds _TRIM_K robust standard
# deviations (1.4826 x median residual) of all matches, and at least _TRIM_FLOOR x the gate.
_TRIM_K = 2.0
_TRIM_FLOOR = 0.5



def layout_spacing(points) -> float:
    """The median distance from a point to its nearest neighbour (the layout's scale).

    Parameters
    ----------
    points : (P, d) float
        P >= 2 points.

    Returns
    -------
    float
    """
    d = np.linalg.norm(points[:, None] - points[None], axis=2)
    np.fill_diagonal(d, np.inf)
    return float(np.median(d.min(1)))

def assign(points: np.ndarray, dots: np.ndarray, gates: np.ndarray) -> np.ndarray:
    """One-to-one nearest assignment within per-point gates; -1 where none. (P,) int."""
    out = np.full(len(points), -1, dtype=np.int64)
    ok_pts = np.all(np.isfinite(points), axis=1)
    if len(dots) == 0 or not ok_pts.any():
        return out
    dist = np.linalg.norm(points[:, None, :] - dots[None, :, :], axis=2)
    dist[~ok_pts] = np.inf
    cost = np.where(dist <= gates[:, None], dist, _BIG)
    rows, cols = linear_sum_assignment(cost)
    good = cost[rows, cols] < _BIG
    out[rows[good]] = cols[good]
    return out


def similarity_2d(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Least-squares 2-D similarity (s, R, t) with dst ~ s R src + t (Umeyama)."""
    ms, md = src.mean(0), dst.mean(0)
    a, b = src - ms, dst - md
    U, S, Vt = np.linalg.svd(b.T @ a)
    d = np.diag([1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    R = U @ d @ Vt
    var = (a * a).sum()
    s = float(np.trace(np.diag(S) @ d) / var) if var > 0 else 1.0
    return s, R, md - s * R @ ms


def _hypotheses(dots: np.ndarray, expected: np.ndarray, gate: float) -> np.ndarray:
    """The best similarity from two-point correspondences (RANSAC over all dot pairs).

    For a few well-separated pairs of layout points, every ordered pair of dots defines a
    similarity (as complex numbers, z -> a z + b); the one that brings the most layout points
    within ``gate`` of some dot wins. Returns the moved layout (P, 2).
    """
    if len(dots) < 2:  # no pair of dots: no hypothesis
        return expected
    e = expected[:, 0] + 1j * expected[:, 1]
    d = dots[:, 0] + 1j * dots[:, 1]
    tree = cKDTree(dots)
    centred = expected - expected.mean(0)
    _, _, axes = np.linalg.svd(centred, full_matrices=False)
    proj = centred @ axes.T
    ends = {int(np.argmin(proj[:, 0])), int(np.argmax(proj[:, 0])), int(np.argmin(proj[:, 1])),
            int(np.argmax(proj[:, 1]))}
    ends = sorted(ends)
    pairs = [(a, b) for i, a in enumerate(ends) for b in ends[i + 1:]]
    ii, jj = np.nonzero(~np.eye(len(d), dtype=bool))
    best, best_key = expected, (-1, 0.0)
    for a, b in pairs:
        if abs(e[b] - e[a]) < 1e-9:
            continue
        z = (d[jj] - d[ii]) / (e[b] - e[a])
        plausible = (np.abs(z) > 0.5) & (np.abs(z) < 2.0) & (np.abs(np.angle(z)) < np.deg2rad(60))
        z, off = z[plausible], d[ii][plausible] - z[plausible] * e[a]
        if len(z) == 0:
            continue
        moved = z[:, None] * e[None, :] + off[:, None]                        # (H, P)
        near = _nearest_within(tree, d, moved, gate)                          # (H, P)
        inliers = (near < gate).sum(1)
        spread = -np.minimum(near, gate).sum(1)
        h = int(np.lexsort((spread, inliers))[-1])
        if (int(inliers[h]), float(spread[h])) > best_key:
            best_key = (int(inliers[h]), float(spread[h]))
            best = np.column_stack([moved[h].real, moved[h].imag])
    return best


def _nearest_within(tree, d: np.ndarray, moved: np.ndarray, gate: float) -> np.ndarray:
    """``|moved - d|`` to the nearest dot (complex, as ``moved (H, P)`` and ``d (k,)``) where one is
    within ``gate``, else inf: what the hypotheses' count and spread need, without the (H, P, k)
    array of every distance (a frame's texture makes k several hundred: 0.3 s per call on ``hard``).
    The two nearest by the tree are measured as the dense version measured them, so the values are
    the same to the bit."""
    pts = np.column_stack([moved.real.ravel(), moved.imag.ravel()])
    k = min(2, len(d))
    _, idx = tree.query(pts, k=k, distance_upper_bound=gate * (1 + 1e-6) + 1e-9)
    idx = idx.reshape(len(pts), k)
    near = np.full(len(pts), np.inf)
    for c in range(k):
        found = idx[:, c] < len(d)
        near[found] = np.minimum(near[found], np.abs(moved.ravel()[found] - d[idx[found, c]]))
    return near.reshape(moved.shape)


def _icp(dots: np.ndarray, expected: np.ndarray, start: np.ndarray, gate: float, iterations: int
         ) -> tuple[np.ndarray, np.ndarray]:
    cur, current_gate = start, 4.0 * gate
    match = assign(cur, dots, np.full(len(expected), current_gate))
    for _ in range(iterations):
        m = match >= 0
        if m.sum() < 2:
            break
        s, R, t = similarity_2d(expected[m], dots[match[m]])
        cur = s * expected @ R.T + t
        current_gate = max(0.8 * current_gate, gate)
        new = assign(cur, dots, np.full(len(expected), current_gate))
        if np.array_equal(new, match) and current_gate == gate:
            break
        match = new
    return assign(cur, dots, np.full(len(expected), gate)), cur


def register_points(dots: np.ndarray, expected: np.ndarray, gate: float, iterations: int = 30,
                    accept: float = 0.8) -> tuple[np.ndarray, np.ndarray]:
    """Align a marker layout to detected dots: 2-D similarity ICP with one-to-one matching.

    ICP from the layout as given (alternately assign one-to-one within a gate shrinking from
    ``4 * gate`` to ``gate``, and refit the similarity mapping the layout onto its dots); the
    layout left where it is wins if it has more dots within ``gate``. When
    that matches fewer than ``accept`` of the markers, the start is instead the best two-point
    RANSAC hypothesis over all dot pairs, which finds large rotations, scalings, jumps and
    clutter that ICP alone would fall into a wrong neighbour for.

    Parameters
    ----------
    dots : (k, 2) float
        Detected dot centres.
    expected : (P, 2) float
        The layout: where each marker should be, roughly (shape matters more than placement).
    gate : float
        Largest residual (pixels) of a match after alignment.

    Returns
    -------
    match : (P,) int
        Index into ``dots`` for each marker, -1 where no dot matches.
    aligned : (P, 2) float
        The layout moved by the fitted similarity (the best guess for unmatched markers too).
    """
    dots = as_float_array(dots, "dots", (None, 2))
    expected = as_float_array(expected, "expected", (None, 2))
    if len(dots) == 0 or len(expected) == 0:
        return np.full(len(expected), -1, dtype=np.int64), expected
    match, cur = _icp(dots, expected, expected, gate, iterations)
    # ICP's wide first gate can slide into clutter; never move the layout to where it explains
    # fewer dots than it does as given.
    still = assign(expected, dots, np.full(len(expected), gate))
    if (still >= 0).sum() > (match >= 0).sum():
        match, cur = still, expected
    if (match >= 0).sum() >= accept * len(expected) or len(dots) < 2 or len(expected) < 2:
        return match, cur
    alt_match, alt_cur = _icp(dots, expected, _hypotheses(dots, expected, gate), gate, iterations)
    if (alt_match >= 0).sum() > (match >= 0).sum():
        return alt_match, alt_cur
    return match, cur


def _trim(match: np.ndarray, cur: np.ndarray, dots: np.ndarray, gate: float, k: float = _TRIM_K
          ) -> np.ndarray:
    """Unmatch the matches whose residual (dot - ``cur``) is an outlier among all matches'. (P,) int."""
    m = np.flatnonzero(match >= 0)
    if len(m) < 3:
        return match
    r = np.linalg.norm(dots[match[m]] - cur[m], axis=1)
    limit = max(k * 1.4826 * float(np.median(r)), _TRIM_FLOOR * gate)
    out = match.copy()
    out[m[r > limit]] = -1
    return out


def _trimmed_similarity(dots: np.ndarray, expected: np.ndarray, match: np.ndarray, cur: np.ndarray,
                        gate: float, iterations: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Refit the similarity on the inlier matches only (trimmed ICP). ((P,) int, (P, 2))."""
    for _ in range(iterations):
        inl = _trim(match, cur, dots, gate)
        m = inl >= 0
        if m.sum() < 3:
            break
        s, R, t = similarity_2d(expected[m], dots[inl[m]])
        cur = s * expected @ R.T + t
        new = _trim(assign(cur, dots, np.full(len(expected), gate)), cur, dots, gate)
        if np.array_equal(new, match):
            break
        match = new
    return match, cur


def register_nonrigid(dots: np.ndarray, expected: np.ndarray, gate: float, iterations: int = 12,
                      robust: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Align a layout to dots allowing smooth deformation (coherent point drift, simply done).

    After the similarity of :func:`register_points`, alternately assign one-to-one within a
    shrinking gate and move every marker by the Gaussian-weighted mean of its matched
    neighbours' offsets (weights by distance in the layout, width shrinking from four times to
    one typical marker spacing). Neighbouring markers thus move together: when the lower lip has
    dropped, all its markers follow, so one of them does not take its neighbour's dot.

    With ``robust``, lure dots and missing dots weigh less: the similarity is refitted on its
    inlier matches only (trimmed ICP: a match whose residual exceeds 2 robust standard deviations
    of all residuals, and half the gate, is left out), and every deformation step moves the
    layout by the offsets of the inlier matches only.

    Parameters
    ----------
    dots : (k, 2) float
        Detected dot centres.
    expected : (P, 2) float
        The layout.
    gate : float
        Largest residual (pixels) of a final match.
    iterations : int
        Deformation steps.
    robust : bool
        Trim outlier matches (see above).

    Returns
    -------
    match : (P,) int
        Index into ``dots``, -1 where none.
    aligned : (P, 2) float
        The deformed layout.
    """
    match, base = register_points(dots, expected, gate)
    if robust:
        match, base = _trimmed_similarity(dots, expected, match, base, gate)
    if len(dots) == 0 or len(expected) < 3:
        return match, base
    spacing = layout_spacing(expected)
    cur = base
    for k in range(iterations):
        frac = k / max(iterations - 1, 1)
        width = spacing * (4.0 - 3.0 * frac)
        current_gate = gate * (3.0 - 2.0 * frac)
        match = assign(cur, dots, np.full(len(expected), current_gate))
        if robust:
            match = _trim(match, cur, dots, gate)
        m = match >= 0
        if m.sum() < 3:
            break
        offsets = dots[match[m]] - base[m]
        w = np.exp(-0.5 * (np.linalg.norm(expected[:, None] - expected[m][None], axis=2) / width) ** 2)
        cur = base + (w @ offsets) / np.maximum(w.sum(1, keepdims=True), 1e-12)
    return assign(cur, dots, np.full(len(expected), gate)), cur


def match_to_expected(dots: np.ndarray, expected: np.ndarray, gate: float, ratio: float = 0.6,
                      robust: bool = False) -> np.ndarray:
    """Match the first frame's dots to the expected marker positions (the thesis's GUI step).

    After :func:`register_nonrigid`, a match is kept only when it is unambiguous: the dot is
    closer to its marker's aligned position than ``ratio`` times its distance to any other
    marker's, and than ``ratio`` times the distance from that marker to any other dot. Markers
    whose dots cannot be told apart stay unmatched (-1) and are acquired later by the tracker.

    Parameters
    ----------
    dots : (k, 2) float
        Detected dot centres.
    expected : (P, 2) float
        The layout (expected marker positions).
    gate : float
        Largest residual (pixels) of a match.
    ratio : float
        Ambiguity ratio (see above).
    robust : bool
        Trimmed registration (:func:`register_nonrigid`'s ``robust``).

    Returns
    -------
    (P,) int
        Index into ``dots`` for each marker, -1 where none matches.
    """
    match, aligned = register_nonrigid(dots, expected, gate, robust=robust)
    match[_ambiguous(aligned, dots, match, ratio)] = -1
    return match


def _ambiguous(aligned: np.ndarray, dots: np.ndarray, match: np.ndarray, ratio: float) -> np.ndarray:
    """(P,) bool: matches whose dot is not clearly their marker's (see :func:`match_to_expected`)."""
    out = np.zeros(len(match), dtype=bool)
    m = np.flatnonzero(match >= 0)
    if len(m) == 0:
        return out
    d_own = np.linalg.norm(aligned[m] - dots[match[m]], axis=1)
    d_markers = np.linalg.norm(aligned[None, :, :] - dots[match[m]][:, None, :], axis=2)   # (k, P)
    d_markers[np.arange(len(m)), m] = np.inf
    d_dots = np.linalg.norm(aligned[m][:, None, :] - dots[None, :, :], axis=2)            # (k, D)
    d_dots[np.arange(len(m)), match[m]] = np.inf
    d_markers[~np.isfinite(d_markers)] = np.inf
    out[m] = (d_own >= ratio * d_markers.min(1)) | (d_own >= ratio * d_dots.min(1))
    return out
