"""Marker tracking over frames by normalised correlation, with detection as the safety net.

The thesis tracked its ink dots with normalised correlation and fixed the failures by hand in a
GUI (§3). Here the GUI is replaced by two things:

* **Initialisation** (:func:`match_to_expected`): the first frame's detected dots are matched to
  where the model's markers are expected to be (e.g. their projections through the calibrated
  camera) by a robust 2-D similarity ICP with one-to-one (Hungarian) assignment.
* **Recovery**: every frame, each marker is predicted by constant velocity and searched for by
  normalised correlation of its template; the correlation peak (or the prediction, when the peak
  is weak or jumps too far) is then snapped to a detected dot by a one-to-one assignment. The
  position reported is the dot's sub-pixel centroid, so template drift does not accumulate. A
  marker with no dot in reach is marked not visible (``status = LOST``) and re-acquired, with a
  widening gate, when a dot reappears near its prediction.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy.optimize import linear_sum_assignment

from ._validate import as_float_array
from .dots import DotSettings, as_gray, detect_dots

__all__ = [
    "TrackerSettings", "Tracks", "TRACKED", "RECOVERED", "CORRELATION_ONLY", "LOST",
    "normalized_correlation", "register_points", "match_to_expected", "track_markers",
]

TRACKED, RECOVERED, CORRELATION_ONLY, LOST = 0, 1, 2, 3
"""Per-frame status of a marker: correlation agreed with a detected dot; correlation failed and
the dot was found from the motion prediction; no dot detected but a confident correlation peak;
not found (not visible)."""

_BIG = 1e12


@dataclass(frozen=True)
class TrackerSettings:
    """Tracking parameters (pixels unless stated).

    Attributes
    ----------
    dots : DotSettings
        How the ink dots look.
    template_radius : int
        Half-size of the correlation template.
    search_radius : int
        Half-size of the correlation search window around the prediction.
    min_correlation : float
        A correlation peak below this counts as a failure.
    confident_correlation : float
        A peak at least this high is accepted even without a detected dot there.
    gate : float
        Largest distance from the correlation peak to the dot it is snapped to.
    recovery_gate : float
        Largest distance from the prediction to a dot when correlation failed; it grows by
        ``gate`` for every frame the marker has been lost.
    max_jump : float
        A correlation peak farther than this from the prediction is a failure.
    motion_penalty : float
        Correlation given up for a match at the edge of the search window (quadratic in the
        distance from the prediction); breaks ties between look-alike dots.
    """

    dots: DotSettings = DotSettings()
    template_radius: int = 7
    search_radius: int = 14
    min_correlation: float = 0.5
    confident_correlation: float = 0.9
    gate: float = 3.0
    recovery_gate: float = 8.0
    max_jump: float = 12.0
    motion_penalty: float = 0.3


@dataclass(frozen=True, eq=False)
class Tracks:
    """Tracked 2-D marker positions in one view.

    Attributes
    ----------
    uv : (F, P, 2) float
        Positions (column, row) in pixels; NaN where the marker is not visible.
    visible : (F, P) bool
    status : (F, P) int8
        ``TRACKED``, ``RECOVERED``, ``CORRELATION_ONLY`` or ``LOST``.
    score : (F, P) float
        Correlation peak (NaN in the first frame and where no search was made).
    """

    uv: np.ndarray
    visible: np.ndarray
    status: np.ndarray
    score: np.ndarray

    @property
    def n_frames(self) -> int:
        return self.uv.shape[0]

    @property
    def n_markers(self) -> int:
        return self.uv.shape[1]


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
    win = sliding_window_view(search, template.shape)
    mean = win.mean(axis=(2, 3))
    num = np.einsum("ijkl,kl->ij", win, t)            # sum((win - mean) * t) == sum(win * t)
    var = (win * win).sum(axis=(2, 3)) - mean * mean * t.size
    den = np.sqrt(np.maximum(var, 0.0)) * tn
    return np.where(den > 1e-12, num / np.maximum(den, 1e-300), 0.0)


def _parabola_offset(left: float, mid: float, right: float) -> float:
    den = left - 2.0 * mid + right
    return 0.0 if den >= 0 else float(np.clip(0.5 * (left - right) / den, -0.5, 0.5))


def _patch(gray: np.ndarray, center: np.ndarray, radius: int) -> np.ndarray:
    """Square patch of side 2*radius+1 around the rounded centre, edge-padded."""
    c, r = np.round(center).astype(np.int64)
    h, w = gray.shape
    rows = np.clip(np.arange(r - radius, r + radius + 1), 0, h - 1)
    cols = np.clip(np.arange(c - radius, c + radius + 1), 0, w - 1)
    return gray[np.ix_(rows, cols)]


def _correlate(gray: np.ndarray, template: np.ndarray, center: np.ndarray, radius: int,
               penalty: float) -> tuple[np.ndarray, float]:
    """Best placement of ``template`` within ``radius`` of ``center``: (uv, peak score).

    Every ink dot looks like every other, so the peak is chosen on the correlation minus
    ``penalty * (distance / radius)^2``: of two equally good matches, the one nearer the
    prediction wins. The score returned is the plain correlation there.
    """
    t_rad = template.shape[0] // 2
    search = _patch(gray, center, radius + t_rad)
    ncc = normalized_correlation(search, template)
    off = (np.arange(ncc.shape[0]) - radius) / max(radius, 1)
    prior = penalty * (off[:, None] ** 2 + off[None, :] ** 2)
    i, j = np.unravel_index(int(np.argmax(ncc - prior)), ncc.shape)
    di = _parabola_offset(ncc[i - 1, j], ncc[i, j], ncc[i + 1, j]) if 0 < i < ncc.shape[0] - 1 else 0.0
    dj = _parabola_offset(ncc[i, j - 1], ncc[i, j], ncc[i, j + 1]) if 0 < j < ncc.shape[1] - 1 else 0.0
    base = np.round(center)
    uv = np.array([base[0] - radius + j + dj, base[1] - radius + i + di])
    return uv, float(ncc[i, j])


def _assign(points: np.ndarray, dots: np.ndarray, gates: np.ndarray) -> np.ndarray:
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


def _assign_two_routes(cand: np.ndarray, pred: np.ndarray, dots: np.ndarray, gates: np.ndarray,
                       pred_gates: np.ndarray, corr_ok: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One-to-one assignment of markers to dots, preferring the correlation peak.

    A dot within ``gates`` of a marker's correlation peak costs its distance; a dot within
    ``pred_gates`` of the motion prediction costs that distance plus the largest peak gate, so it
    is taken only when the peak route is not available (the correlation locked onto a dot
    another marker owns, or failed). Returns (match (P,) int, -1 for none; via_correlation (P,)).
    """
    out = np.full(len(cand), -1, dtype=np.int64)
    via = np.zeros(len(cand), dtype=bool)
    ok = np.all(np.isfinite(pred), axis=1)
    if len(dots) == 0 or not ok.any():
        return out, via
    d_cand = np.linalg.norm(cand[:, None] - dots[None], axis=2)
    d_pred = np.linalg.norm(pred[:, None] - dots[None], axis=2)
    peak_route = corr_ok[:, None] & (d_cand <= gates[:, None])
    pred_route = d_pred <= pred_gates[:, None]
    cost = np.where(peak_route, d_cand, np.where(pred_route, d_pred + gates.max() + 1.0, _BIG))
    cost[~ok] = _BIG
    rows, cols = linear_sum_assignment(cost)
    good = cost[rows, cols] < _BIG
    out[rows[good]] = cols[good]
    via[rows[good]] = peak_route[rows[good], cols[good]]
    return out, via


def _similarity_2d(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
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
    e = expected[:, 0] + 1j * expected[:, 1]
    d = dots[:, 0] + 1j * dots[:, 1]
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
        near = np.abs(moved[:, :, None] - d[None, None, :]).min(axis=2)       # (H, P)
        inliers = (near < gate).sum(1)
        spread = -np.minimum(near, gate).sum(1)
        h = int(np.lexsort((spread, inliers))[-1])
        if (int(inliers[h]), float(spread[h])) > best_key:
            best_key = (int(inliers[h]), float(spread[h]))
            best = np.column_stack([moved[h].real, moved[h].imag])
    return best


def _icp(dots: np.ndarray, expected: np.ndarray, start: np.ndarray, gate: float, iterations: int
         ) -> tuple[np.ndarray, np.ndarray]:
    cur, current_gate = start, 4.0 * gate
    match = _assign(cur, dots, np.full(len(expected), current_gate))
    for _ in range(iterations):
        m = match >= 0
        if m.sum() < 2:
            break
        s, R, t = _similarity_2d(expected[m], dots[match[m]])
        cur = s * expected @ R.T + t
        current_gate = max(0.8 * current_gate, gate)
        new = _assign(cur, dots, np.full(len(expected), current_gate))
        if np.array_equal(new, match) and current_gate == gate:
            break
        match = new
    return _assign(cur, dots, np.full(len(expected), gate)), cur


def register_points(dots: np.ndarray, expected: np.ndarray, gate: float, iterations: int = 30,
                    accept: float = 0.8) -> tuple[np.ndarray, np.ndarray]:
    """Align a marker layout to detected dots: 2-D similarity ICP with one-to-one matching.

    ICP from the layout as given (alternately assign one-to-one within a gate shrinking from
    ``4 * gate`` to ``gate``, and refit the similarity mapping the layout onto its dots). When
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
    if (match >= 0).sum() >= accept * len(expected) or len(dots) < 2 or len(expected) < 2:
        return match, cur
    alt_match, alt_cur = _icp(dots, expected, _hypotheses(dots, expected, gate), gate, iterations)
    if (alt_match >= 0).sum() > (match >= 0).sum():
        return alt_match, alt_cur
    return match, cur


def match_to_expected(dots: np.ndarray, expected: np.ndarray, gate: float) -> np.ndarray:
    """Match the first frame's dots to the expected marker positions (the thesis's GUI step).

    Returns
    -------
    (P,) int
        Index into ``dots`` for each marker, -1 where none matches (see :func:`register_points`).
    """
    return register_points(dots, expected, gate)[0]


def _predict(last: np.ndarray, vel: np.ndarray, gap: np.ndarray, reference: np.ndarray | None,
             dots: np.ndarray, gate: float) -> np.ndarray:
    """Where each marker should be in this frame, NaN if unknown.

    Constant velocity from the last sighting, corrected by the similarity that best aligns the
    predicted layout with this frame's dots (this catches sudden global jumps, which would
    otherwise take the correlation to a neighbouring dot). Markers never seen are placed by the
    similarity from the reference layout onto the seen ones.
    """
    pred = last + vel * (gap + 1)[:, None]
    known = np.all(np.isfinite(pred), axis=1)
    if known.sum() >= 3 and len(dots) >= 3:
        match, aligned = register_points(dots, pred[known], gate)
        if (match >= 0).sum() >= max(3, known.sum() // 2):
            pred[known] = aligned
    if reference is not None and (~known).any() and known.sum() >= 2:
        s, R, t = _similarity_2d(reference[known], pred[known])
        pred[~known] = s * reference[~known] @ R.T + t
    return pred


def _carry_lost_markers(last: np.ndarray, uv: np.ndarray, visible: np.ndarray, gap: np.ndarray) -> None:
    """Move the last-seen positions of lost markers with the markers seen in both frames.

    Without this a lost marker waits where it was last seen while the face moves on, and its
    search misses it when it reappears. Updates ``last`` in place.
    """
    pairs = visible & (gap == 0) & np.all(np.isfinite(last), axis=1)
    lost = ~visible & np.all(np.isfinite(last), axis=1)
    if lost.any() and pairs.sum() >= 3:
        s, R, t = _similarity_2d(last[pairs], uv[pairs])
        last[lost] = s * last[lost] @ R.T + t


def track_markers(frames: Iterable, initial_uv: np.ndarray,
                  settings: TrackerSettings = TrackerSettings(),
                  reference_uv: np.ndarray | None = None) -> Tracks:
    """Track markers through a sequence of images of one view.

    Parameters
    ----------
    frames : iterable of (h, w) or (h, w, 3) arrays
        The images, in order (read lazily, one at a time).
    initial_uv : (P, 2) float
        Marker positions in the first frame, NaN for markers not found there (for example from
        :func:`match_to_expected` on the first frame's :func:`~lipgen.dots.detect_dots`).
    settings : TrackerSettings
    reference_uv : (P, 2) float, optional
        The expected layout of all markers (e.g. their projections at rest). With it, a marker
        not seen yet is searched for where the layout, aligned to the seen markers, puts it.

    Returns
    -------
    Tracks
    """
    init = as_float_array(initial_uv, "initial_uv", (None, 2), finite=False)
    P = len(init)
    if reference_uv is not None:
        reference_uv = as_float_array(reference_uv, "reference_uv", (P, 2))
    cfg = settings
    uv_all, vis_all, st_all, sc_all = [], [], [], []
    last = init.copy()                      # last seen position (NaN if never seen)
    vel = np.zeros((P, 2))
    gap = np.zeros(P, dtype=np.int64)       # frames since last seen
    # Each template is a patch around the rounded centroid plus the centroid's sub-pixel offset.
    templates: list[tuple[np.ndarray, np.ndarray] | None] = [None] * P
    for t, image in enumerate(frames):
        gray = as_gray(image)
        dots, _ = detect_dots(gray, cfg.dots)
        uv = np.full((P, 2), np.nan)
        status = np.full(P, LOST, dtype=np.int8)
        score = np.full(P, np.nan)
        if t == 0:
            seen = np.all(np.isfinite(init), axis=1)
            # Snap the given positions to this frame's dots so every position is a centroid.
            snap = _assign(init, dots, np.where(seen, cfg.gate, 0.0))
            uv[seen] = init[seen]
            uv[snap >= 0] = dots[snap[snap >= 0]]
            status[seen] = TRACKED
        else:
            pred = _predict(last, vel, gap, reference_uv, dots, cfg.recovery_gate)
            cand, gates, corr_ok = pred.copy(), np.zeros(P), np.zeros(P, dtype=bool)
            for i in np.flatnonzero(np.all(np.isfinite(pred), axis=1)):
                gates[i] = cfg.recovery_gate + cfg.gate * gap[i]
                if templates[i] is None:
                    continue
                patch, offset = templates[i]
                radius = cfg.search_radius + int(np.ceil(cfg.gate * gap[i]))
                peak, score[i] = _correlate(gray, patch, pred[i], radius, cfg.motion_penalty)
                peak = peak + offset
                if score[i] >= cfg.min_correlation and np.linalg.norm(peak - pred[i]) <= cfg.max_jump:
                    cand[i], corr_ok[i], gates[i] = peak, True, cfg.gate
            snap, via_corr = _assign_two_routes(cand, pred, dots, gates,
                                                cfg.recovery_gate + cfg.gate * gap, corr_ok)
            got = snap >= 0
            uv[got] = dots[snap[got]]
            status[got & via_corr] = TRACKED
            status[got & ~via_corr] = RECOVERED
            trust = ~got & corr_ok & (score >= cfg.confident_correlation)
            uv[trust] = cand[trust]
            status[trust] = CORRELATION_ONLY
        visible = status != LOST
        _carry_lost_markers(last, uv, visible, gap)
        for i in np.flatnonzero(visible):
            if gap[i] == 0 and t > 0 and np.all(np.isfinite(last[i])):
                vel[i] = 0.5 * vel[i] + 0.5 * (uv[i] - last[i])   # damped constant velocity
            else:
                vel[i] = 0.0
            if status[i] != CORRELATION_ONLY:
                templates[i] = (_patch(gray, uv[i], cfg.template_radius).copy(), uv[i] - np.round(uv[i]))
        last[visible] = uv[visible]
        gap[visible] = 0
        gap[~visible & np.all(np.isfinite(last), axis=1)] += 1
        uv_all.append(uv)
        vis_all.append(visible)
        st_all.append(status)
        sc_all.append(score)
    if not uv_all:
        raise ValueError("track_markers got no frames")
    return Tracks(np.stack(uv_all), np.stack(vis_all), np.stack(st_all), np.stack(sc_all))
