"""The first frame's matches, checked jointly in 3-D against the marker layout (lures on the epipolar line).

Each view's first-frame dots are matched to the 2-D layout on its own
(:func:`lipgen.recon.pointreg.match_to_expected`), and a pair whose rays miss is dropped. A lure
lying along the epipolar line of the right dot passes that test: its ray still meets the other
view's, at a point moved along that view's ray. In 3-D the point is then out of place among its
neighbours. So all matched markers are checked together (:func:`check_layout`, a check of the
whole layout across both views, as marker labelling in motion capture checks labels against a
rigid or smoothly deforming template):

* the markers' 3-D points are fitted by the model's layout moved by a trimmed 3-D similarity
  and the smooth local offsets of the markers around each one (the subject's own lip shape, the
  mouth's opening), each marker predicted from the others only (leave one out);
* a marker whose point is farther from its prediction than ``k`` robust standard deviations of
  all residuals (and than ``floor`` mm) is out of place. The view whose dot is far from the
  prediction's projection lost it; where the other view's dot is near the prediction's
  projection, that view's match stands.
* The out-of-place marker takes the pair of free dots (rays within ``max_gap``) whose 3-D point
  is nearest its prediction when that is within the residual limit and unambiguous (nearer than
  ``ratio`` times the next pair); otherwise its wrong view is left unmatched and the tracker
  acquires the marker later (``TrackerSettings.acquire_gate``). Where the mouth is open in the
  first frame, the limit is wide (the layout at rest predicts the lower lip 3-5 mm off); so any
  checked marker over ``floor`` also takes such a pair when it is nearer its prediction than
  ``ratio`` times the match's own residual (a lure at 9 px along the epipolar line at 7.7 mm,
  the marker's own pair nearer).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from lipgen._validate import as_float_array
from lipgen.recon.dots import DotSettings, detect_dots
from lipgen.recon.layoutprior import predict_layout_physics
from lipgen.recon.pointreg import layout_spacing, match_to_expected
from lipgen.recon.stereo_init import _similarity_3d, stereo_candidates
from lipgen.recon.tracks import lowered_floor
from lipgen.rig.pinhole import PinholeCamera, triangulate

__all__ = ["match_first_frame", "match_view", "pale_floor", "first_frame_dots", "predict_layout",
           "check_layout", "checked_matches", "triangulate_matched"]


def match_first_frame(dots, strength, expected, gate: float, robust: bool = False,
                      dark: float | None = 0.4) -> np.ndarray:
    """Match one view's first-frame dots to the layout, on dots about as dark as the markers' ink.

    Faint blobs near the lips (skin texture, the shadow at a lip corner) are lures: a 2-D layout
    that fits the subject's own dots to 2 mm cannot tell them from a marker's dot a few pixels
    away. So the layout is matched once on all dots
    (:func:`~lipgen.recon.pointreg.match_to_expected`), the markers' darkness is taken as the
    median strength of its matched dots, and it is matched again on the dots at least ``dark``
    times that dark.

    Parameters
    ----------
    dots : (k, 2) float
        The view's dots, pixels.
    strength : (k,) float
        Their darkness (:func:`lipgen.recon.dots.detect_dots`).
    expected : (P, 2) float
        The layout.
    gate : float
        Largest residual (pixels) of a match.
    robust : bool
        Trimmed registration (:func:`~lipgen.recon.pointreg.match_to_expected`).
    dark : float or None
        Least darkness of a dot, as a fraction of the matched dots' median; None: all dots.

    Returns
    -------
    (P,) int
        Index into ``dots`` per marker, -1 where none.
    """
    dots = as_float_array(dots, "dots", (None, 2))
    strength = as_float_array(strength, "strength", (len(dots),))
    match = match_to_expected(dots, expected, gate, robust=robust)
    if dark is None or (match >= 0).sum() < 3:
        return match
    keep = np.flatnonzero(strength >= dark * float(np.median(strength[match[match >= 0]])))
    if len(keep) == len(dots) or len(keep) < 3:
        return match
    sub = match_to_expected(dots[keep], expected, gate, robust=robust)
    return np.where(sub >= 0, keep[np.maximum(sub, 0)], -1)


def pale_floor(strength, min_contrast: float, ratio: float, least: float) -> float | None:
    """The first frame's contrast floor for a view whose matched dots have darkness ``strength (m,)``.

    The tracker lowers a pale view's floor from the second image on
    (:meth:`lipgen.recon.tracks.TrackerSettings.dots_for`: ``ratio`` x the median darkness of its
    markers' dots, never under ``least``); this is the same rule on the first frame's own matches,
    where no marker's darkness is known yet. Returns None where the floor stays: no matches, or
    ``ratio`` x the median is not under ``min_contrast``.
    """
    s = np.asarray(strength, dtype=float)
    return None if s.size == 0 else lowered_floor(float(np.median(s)), ratio, min_contrast, least)


def first_frame_dots(views, dots: DotSettings, expected, gate: float, robust: bool, dark: float | None,
                     ratio: float | None, least: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each view's first-frame dots, found again at a lowered floor where the view is pale.

    The mirror of the ``hard`` preset (reflectance 0.85, defocus, ghost) halves the markers'
    darkness: on ``hard`` 35, 56, 58 and 64 frame 0 most of the mirror's marks that are missed
    have a round response peak within 1.5 px, but under the fixed floor 0.08 (0.03-0.078),
    where the direct view's reach 0.08-0.33. A wider detector scale finds fewer of them
    (``renders/examples/tracking/collapse19_first_frame.md``). So each view is matched once at
    the fixed floor (:func:`match_first_frame`), and where :func:`pale_floor` lowers the floor
    from its matched dots the view is detected again with it.

    Parameters
    ----------
    views : (virtual, real) images
    dots : DotSettings
        The detector at its fixed floor.
    expected : (2, P, 2) float
        The layout in each view (NaN rows: not projected).
    gate, robust, dark
        As :func:`match_first_frame`.
    ratio : float or None
        Share of the matched dots' median darkness the floor is lowered to; None: never lowered.
    least : float
        The lowered floor's least value.

    Returns
    -------
    list of (uv (k, 2), strength (k,)) per view, as :func:`lipgen.recon.dots.detect_dots`.
    """
    found = []
    for img, exp in zip(views, expected, strict=True):
        uv, strength = detect_dots(img, dots)
        floor = None if ratio is None else _view_floor(uv, strength, exp, gate, robust, dark, ratio,
                                                       least, dots.min_contrast)
        found.append((uv, strength) if floor is None else detect_dots(img, replace(dots, min_contrast=floor)))
    return found


def _view_floor(uv, strength, expected, gate, robust, dark, ratio, least, min_contrast) -> float | None:
    """:func:`pale_floor` of the dots one view's first-frame match takes (see :func:`first_frame_dots`)."""
    if len(uv) == 0:
        return None
    match = match_view(uv, strength, expected, gate, robust, dark)
    return pale_floor(strength[match[match >= 0]], min_contrast, ratio, least)


def match_view(dots, strength, expected, gate: float, robust: bool = False, dark: float | None = None
               ) -> np.ndarray:
    """(P,) int: :func:`match_first_frame` of one view's ``dots`` to the projected rows of ``expected
    (P, 2)`` (NaN rows: not projected, -1 there, as for a marker left unmatched)."""
    ok = np.all(np.isfinite(expected), axis=1)
    match = np.full(len(ok), -1)
    if ok.any():
        match[ok] = match_first_frame(dots, strength, expected[ok], gate, robust, dark)
    return match


def predict_layout(model: np.ndarray, points: np.ndarray, use: np.ndarray, width: float,
                   covariance: np.ndarray | None = None) -> np.ndarray:
    """Each marker's 3-D position predicted from the other used markers (leave one out).

    The similarity from ``model[use]`` to ``points[use]``, then the Gaussian-weighted mean (width
    ``width`` mm in the layout) of the used markers' residual offsets, each marker's own left out.
    With ``covariance``, the physics prior instead
    (:func:`lipgen.recon.layoutprior.predict_layout_physics`; ``width`` is not used).

    Parameters
    ----------
    model : (P, 3) float
        The marker layout (the model's markers at rest), mm.
    points : (P, 3) float
        The markers' points, mm; read where ``use``.
    use : (P,) bool
        Markers the prediction is made from (at least 4).
    width : float
        Width of the offsets' weights, mm.
    covariance : (3P, 3P) float, optional
        The layout's prior covariance in the frame of ``model``
        (:func:`lipgen.recon.layoutprior.physics_layout_covariance`).

    Returns
    -------
    (P, 3) float
        Predicted positions (for used markers, from the others).
    """
    if covariance is not None:
        return predict_layout_physics(model, points, use, covariance)
    P = len(model)
    out = np.full((P, 3), np.nan)
    idx = np.flatnonzero(use)
    for i in range(P):
        others = idx[idx != i]
        if len(others) < 4:
            continue
        T = _similarity_3d(model[others], points[others])
        base = model @ T[:3, :3].T + T[:3, 3]
        w = np.exp(-0.5 * (np.linalg.norm(model[others] - model[i], axis=1) / width) ** 2)
        off = (w @ (points[others] - base[others])) / max(float(w.sum()), 1e-300)
        out[i] = base[i] + off
    return out


def _residuals(model, points, use, width, k, floor, rounds: int = 3,
               covariance=None) -> tuple[np.ndarray, np.ndarray, float]:
    """Leave-one-out residuals with the out-of-place markers left out of the prediction.

    Returns (pred (P, 3), residual (P,), limit mm)."""
    inl = use.copy()
    for _ in range(rounds):
        pred = predict_layout(model, points, inl, width, covariance)
        r = np.linalg.norm(points - pred, axis=1)
        sigma = 1.4826 * float(np.median(r[inl & np.isfinite(r)]))
        limit = max(k * sigma, floor)
        new = use & (r <= limit)
        if new.sum() < 5 or np.array_equal(new, inl):
            break
        inl = new
    return pred, r, limit


def check_layout(inits: list[np.ndarray], dots: list[np.ndarray],
                 cameras: tuple[PinholeCamera, PinholeCamera], model_points, max_gap: float,
                 k: float = 4.0, floor: float = 1.0, px_tol: float = 2.0,
                 ratio: float = 0.6, covariance=None) -> tuple[list[np.ndarray], np.ndarray]:
    """Check the first frame's matches of both views jointly against the 3-D layout; fix or drop the wrong.

    Parameters
    ----------
    inits : (virtual, real) (P, 2) float
        Each view's first-frame matches (dot centres), NaN where unmatched.
    dots : (virtual, real) (m, 2), (n, 2) float
        All dots found in each view's first frame.
    cameras : (virtual, real) PinholeCamera
    model_points : (P, 3) float
        The markers at rest in the frame of ``cameras``, mm (NaN rows: markers without a layout).
    max_gap : float
        Largest distance between two rays of a pair, mm.
    k, floor : float
        A marker is out of place when its point is farther from its leave-one-out prediction than
        ``k`` robust standard deviations (1.4826 x median) of the residuals and than ``floor`` mm.
    px_tol : float
        A view's match stands when its dot is within this many pixels of the prediction's
        projection; the view farther from it loses its match (both when both are farther).
    ratio : float
        A replacement pair must be nearer its prediction than ``ratio`` times the next pair.
    covariance : (3P, 3P) float, optional
        Predict with the physics prior (:func:`predict_layout`); None: the offsets' mean.

    Returns
    -------
    inits : (virtual, real) (P, 2) float
        The checked matches (copies).
    changed : (2, P) bool
        The matches changed or dropped, per view.
    """
    model, out = checked_matches(model_points, inits)
    P = len(model)
    changed = np.zeros((2, P), dtype=bool)
    both = np.all(np.isfinite(out[0]), axis=1) & np.all(np.isfinite(out[1]), axis=1)
    both &= np.all(np.isfinite(model), axis=1)
    if both.sum() < 6:
        return out, changed
    X = triangulate_matched(cameras, out, both)
    width = layout_spacing(model[both])
    pred, r, limit = _residuals(model, X, both, width, k, floor, covariance=covariance)
    # A marker far from all others (the nose) is not predicted by their offsets: not checked.
    near = np.linalg.norm(model[:, None] - model[both][None], axis=2)
    near[near == 0] = np.inf
    checked = both & (near.min(1) <= 2.5 * width)
    bad = checked & (r > limit)
    cand_X, pairs = stereo_candidates(dots[0], dots[1], cameras, max_gap)
    for i in np.flatnonzero(checked & (r > floor)):
        proj = [cameras[v].project(pred[i][None])[0] for v in range(2)]
        err = np.array([np.linalg.norm(out[v][i] - proj[v]) for v in range(2)])
        # Dots the other markers hold are not free.
        taken = [np.zeros(len(dots[v]), dtype=bool) for v in range(2)]
        for v in range(2):
            held = np.all(np.isfinite(out[v]), axis=1)
            held[i] = False
            if len(dots[v]) and held.any():
                taken[v] = np.linalg.norm(dots[v][:, None] - out[v][held][None], axis=2).min(1) < 0.5
        free = ~taken[0][pairs[:, 0]] & ~taken[1][pairs[:, 1]] if len(pairs) else np.zeros(0, dtype=bool)
        dist = np.linalg.norm(cand_X[free] - pred[i], axis=1) if free.any() else np.zeros(0)
        order = np.argsort(dist)
        clear = len(order) == 1 or (len(order) > 1 and dist[order[0]] < ratio * dist[order[1]])
        # A pair of free dots much nearer the prediction than the match (within the limit, or
        # under ``ratio`` times the match's own residual) replaces it.
        if len(order) and clear and dist[order[0]] <= (limit if bad[i] else ratio * r[i]):
            pv, pr = pairs[free][order[0]]
            new = [dots[0][pv], dots[1][pr]]
            for v in range(2):
                if not np.allclose(new[v], out[v][i]):
                    out[v][i], changed[v, i] = new[v], True
            continue
        if not bad[i]:
            continue
        # No clear replacement: the view whose dot is off the prediction loses its match (both if
        # neither is near).
        for v in range(2):
            if err[v] > px_tol and err[v] >= err[1 - v] or err[1 - v] > px_tol and err[v] > px_tol:
                out[v][i], changed[v, i] = np.nan, True
    return out, changed


def _consensus(model: np.ndarray, X: np.ndarray, seeds: np.ndarray, tol: float, share: float = 0.1
               ) -> np.ndarray:
    """The largest set of seeds whose mutual distances are the layout's (a compatibility clique).

    Seeds ``i`` and ``j`` are compatible when their points' distance differs from their layout
    distance by at most ``tol + share * layout distance`` mm (the subject's own lip shape, its
    scale). A wrong pair both views matched sits along a ray, away from where its neighbours put
    it; the largest clique of compatible seeds (ties: the smallest summed misfit) is kept.
    Returns (P,) bool.
    """
    idx = np.flatnonzero(seeds)
    n = len(idx)
    dm = np.linalg.norm(model[idx][:, None] - model[idx][None], axis=2)
    dx = np.linalg.norm(X[idx][:, None] - X[idx][None], axis=2)
    misfit = np.abs(dx - dm)
    ok = misfit <= tol + share * dm
    best, best_key = np.zeros(1, dtype=np.int64), (1, 0.0)

    def extend(clique: list[int], cand: list[int]) -> None:
        nonlocal best, best_key
        if len(clique) + len(cand) < best_key[0]:
            return
        if not cand:
            key = (len(clique), -float(misfit[np.ix_(clique, clique)].sum()))
            if key > best_key:
                best, best_key = np.array(clique), key
            return
        for k, c in enumerate(cand):
            extend(clique + [c], [d for d in cand[k + 1:] if ok[c, d]])

    extend([], list(range(n)))
    out = np.zeros_like(seeds)
    out[idx[best]] = True
    return out


def checked_matches(model_points, inits) -> tuple[np.ndarray, list[np.ndarray]]:
    """The rest layout and a copy of each view's first-frame matches, checked.

    Parameters
    ----------
    model_points : (P, 3) float
        The markers' rest points (NaN rows allowed).
    inits : (virtual, real) (P, 2) float
        Each view's matches (NaN: unmatched).

    Returns
    -------
    model : (P, 3) float
    out : list of two (P, 2) float
        Copies of the matches.
    """
    model = as_float_array(model_points, "model_points", (None, 3), finite=False)
    out = [as_float_array(u, "inits", (len(model), 2), finite=False).copy() for u in inits]
    return model, out


def triangulate_matched(cameras, inits, mask: np.ndarray) -> np.ndarray:
    """3-D points of the markers matched in both views.

    Parameters
    ----------
    cameras : (virtual, real) PinholeCamera
    inits : (virtual, real) (P, 2) float
        Each view's matches.
    mask : (P,) bool
        The markers to triangulate (matched in both views).

    Returns
    -------
    X : (P, 3) float
        Their points; NaN elsewhere.
    """
    X = np.full((len(mask), 3), np.nan)
    X[mask] = triangulate(cameras[1], inits[1][mask], cameras[0], inits[0][mask])[0]
    return X
