"""The first frame grown from a few confident markers, in 3-D along the epipolar lines.

On ``hard`` frames the mirror view is out of focus: the 2-D match of its first frame to the
layout (:func:`lipgen.recon.firstframe.match_first_frame`) holds only 4-10 of 17 markers, while
the direct view holds most. Multi-camera marker labelling in motion capture starts the same way:
a few markers labelled with confidence fix the subject's pose, the template (here the markers
at rest) placed by that pose predicts where every other marker is in 3-D, and a marker is
labelled where a reconstructed point lies near its prediction, unambiguously; each new label
improves the placement of the rest. So :func:`grow_first_frame`:

* seeds with the markers matched in both views (their rays meet: the caller checked the ray gap
  and the 3-D layout, :func:`lipgen.recon.firstframe.check_layout`);
* places the layout on the seeds: a 3-D similarity (its scale near 1; a translation only while
  the seeds lie on a line or would turn it more than 15 degrees) and, from 4 seeds on, the
  seeds' smooth local offsets (the subject's own lip shape, the mouth's opening), shrunk towards
  none far from every seed;
* for each marker not seeded, takes the 3-D points of the pairs of dots whose rays meet (within
  ``max_gap``): a dot of the view that matched it with every free dot of the other view (the dot
  along its epipolar line), or two free dots where neither view matched it;
* adds the one marker whose nearest point is nearest its prediction, within ``near`` and
  unambiguous (nearer than ``ratio`` times the next point, and nearer this marker's prediction
  than any other unseeded marker's), then places the layout again, until none is left. A lure
  on the epipolar line meets the ray too, but at a point moved along it: off the prediction.

A view's own match is replaced by a pair without it only when that pair is nearer the
prediction than ``ratio`` times the match's ray is from it (a wrong 2-D match, whose ray misses
the prediction).

The layout is a weak prior on ``hard`` subjects: placed on right seeds, it puts the other
markers 2-5 mm from their points (the marker spacing is 5 mm), hence ``near`` = 0.8 spacing and
the one-at-a-time growth, which lets each new marker's offset correct its neighbours'.
Measured with ``first_frame_grow`` and ``acquire_pending`` together (main b0a1c18 before, the
same cached calibrations, calibrate -> track -> triangulate scored against the truth; load
24-39): see ``ReconstructSettings.acquire_pending``. The first-frame stage alone, run on frames
0, 10, 20 and 30 of hard validation seeds 7-10 as if each were the first (16 frames): markers
matched right in both views 86 -> 126 of 272, wrong matches (mirror / direct) 32 / 39 -> 34 / 38.
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen._validate import as_float_array
from lipgen.recon.firstframe import _consensus, check_layout, checked_matches, triangulate_matched
from lipgen.recon.pointreg import layout_spacing
from lipgen.recon.seedview import moves_pairs, seed_from_one_view
from lipgen.recon.stereo_init import _similarity_3d, stereo_candidates
from lipgen.rig.camera import VIEWS
from lipgen.rig.pinhole import PinholeCamera, triangulate

__all__ = ["place_layout_3d", "grow_first_frame", "check_first_frame", "paired_markers"]

log = logging.getLogger(__name__)


def place_layout_3d(model: np.ndarray, points: np.ndarray, seeds: np.ndarray, width: float,
                    prior: float = 0.5, max_turn: float = 15.0) -> np.ndarray:
    """Every marker's 3-D position from the seeded markers' points: similarity and local offsets.

    Parameters
    ----------
    model : (P, 3) float
        The marker layout (the markers at rest), mm.
    points : (P, 3) float
        The markers' points, mm; read where ``seeds``.
    seeds : (P,) bool
        At least 3 markers.
    width : float
        Width (mm, in the layout) of the Gaussian weights of the seeds' offsets.
    prior : float
        Weight of "no offset" in each marker's weighted mean of the seeds' offsets (one seed at
        the marker itself weighs 1), so a marker far from every seed keeps the similarity.
    max_turn : float
        Largest rotation (degrees) from the layout's frame; a similarity that turns more (the
        markers are given at rest in the cameras' frame, and the head is placed about so) is
        replaced by the seeds' mean translation.

    Returns
    -------
    (P, 3) float
        The placed layout, mm (seeds too: where the others and their own offset put them).
    """
    model = as_float_array(model, "model", (None, 3))
    points = as_float_array(points, "points", (len(model), 3), finite=False)
    seeds = np.asarray(seeds, dtype=bool)
    if seeds.shape != (len(model),) or seeds.sum() < 3 or not np.all(np.isfinite(points[seeds])):
        raise ValueError(f"seeds must be a ({len(model)},) bool mask of at least 3 finite points, "
                         f"got shape {seeds.shape} with {int(seeds.sum())} set")
    src, dst = model[seeds], points[seeds]
    sv = np.linalg.svd(src - src.mean(0), compute_uv=False)
    base = model + (dst.mean(0) - src.mean(0))
    if sv[1] >= 0.2 * sv[0]:      # not on a line (the rotation about it would be unknown)
        T = _similarity_3d(src, dst)
        A = T[:3, :3] / np.cbrt(np.linalg.det(T[:3, :3]))
        turn = np.degrees(np.arccos(np.clip((np.trace(A) - 1) / 2, -1.0, 1.0)))
        if turn <= max_turn:      # a larger turn: a wrong seed more likely than the head
            base = model @ T[:3, :3].T + T[:3, 3]
    if seeds.sum() < 4:
        return base
    w = np.exp(-0.5 * (np.linalg.norm(model[:, None] - src[None], axis=2) / width) ** 2)
    return base + (w @ (dst - base[seeds])) / (w.sum(1, keepdims=True) + prior)


def _ray_distance(camera: PinholeCamera, uv: np.ndarray, X: np.ndarray) -> float:
    """Distance (mm) from the point ``X (3,)`` to the ray of pixel ``uv (2,)``."""
    o, d = camera.rays(np.asarray(uv, dtype=float)[None])
    o, d = o[0], d[0] / np.linalg.norm(d[0])
    w = X - o
    return float(np.linalg.norm(w - (w @ d) * d))


def grow_first_frame(inits: list[np.ndarray], dots: list[np.ndarray],
                     cameras: tuple[PinholeCamera, PinholeCamera], model_points, max_gap: float,
                     near: float | None = None, ratio: float = 0.6, min_seeds: int = 3,
                     seed_tol: float = 0.5) -> tuple[list[np.ndarray], np.ndarray]:
    """Match the markers not matched in both views where the layout placed on the seeds puts them.

    Parameters
    ----------
    inits : (virtual, real) (P, 2) float
        Each view's first-frame matches (dot centres), NaN where unmatched. Markers matched in
        both views are the seeds.
    dots : (virtual, real) (m, 2), (n, 2) float
        All dots found in each view's first frame.
    cameras : (virtual, real) PinholeCamera
    model_points : (P, 3) float
        The markers at rest in the frame of ``cameras``, mm (NaN rows: markers without a layout).
    max_gap : float
        Largest distance between the two rays of a pair, mm.
    near : float or None
        Largest distance (mm) from a marker's prediction to its pair's point; None: 0.8 of the
        layout's marker spacing.
    ratio : float
        Ambiguity ratio (see the module's description).
    min_seeds : int
        Fewest seeds to grow from (at least 3).
    seed_tol : float
        Seeds stand when their mutual distances are the layout's within ``seed_tol`` layout
        spacings and 10 % (the largest such set, :func:`_consensus`); the others are grown as
        the unmatched are, their own pair among the candidates, and kept where none is chosen.

    Returns
    -------
    inits : (virtual, real) (P, 2) float
        The grown matches (copies).
    grown : (2, P) bool
        The matches added or changed, per view.
    """
    model, out = checked_matches(model_points, inits)
    P = len(model)
    dv = [as_float_array(d, "dots", (None, 2)) for d in dots]
    if min_seeds < 3:
        raise ValueError(f"min_seeds must be at least 3, got {min_seeds!r}")
    grown = np.zeros((2, P), dtype=bool)
    has = np.all(np.isfinite(model), axis=1)
    matched = [np.all(np.isfinite(u), axis=1) for u in out]
    seeds = matched[0] & matched[1] & has
    if seeds.sum() < min_seeds or len(dv[0]) == 0 or len(dv[1]) == 0:
        return out, grown
    X = triangulate_matched(cameras, out, seeds)
    width = layout_spacing(model[has])
    near = 0.8 * width if near is None else float(near)
    PX, pairs = stereo_candidates(dv[0], dv[1], cameras, max_gap)    # every pair whose rays meet
    # Seeds that agree on the subject's layout. The others are grown like unmatched markers, from
    # their own pair among the rest: a wrong pair both views matched is replaced where a pair is
    # clearly nearer its prediction, and kept otherwise (for the layout check that follows).
    seeds = _consensus(model, X, seeds, seed_tol * width)
    if seeds.sum() < min_seeds:
        return out, grown

    def owner(v: int) -> np.ndarray:
        """Per dot of view v: the marker holding it (-1: free)."""
        own = np.full(len(dv[v]), -1)
        for i in np.flatnonzero(np.all(np.isfinite(out[v]), axis=1)):
            d = np.linalg.norm(dv[v] - out[v][i], axis=1)
            k = int(d.argmin())
            if d[k] < 0.5:
                own[k] = i
        return own

    while True:
        todo = np.flatnonzero(has & ~seeds)
        if len(todo) == 0 or len(pairs) == 0:
            break
        pred = place_layout_3d(model, X, seeds, width)
        owners = [owner(0), owner(1)]
        best = None
        for i in todo:
            # Pairs whose dots are free or this marker's own.
            usable = np.isin(owners[0][pairs[:, 0]], (-1, i)) & np.isin(owners[1][pairs[:, 1]], (-1, i))
            if not usable.any():
                continue
            idx = np.flatnonzero(usable)
            d = np.linalg.norm(PX[idx] - pred[i], axis=1)
            o = np.argsort(d)
            k, dk = idx[o[0]], float(d[o[0]])
            if dk > near or (len(o) > 1 and dk >= ratio * d[o[1]]):
                continue
            # The point must be nearest this marker's prediction among the unseeded markers.
            others = todo[todo != i]
            if len(others) and np.linalg.norm(pred[others] - PX[k], axis=1).min() <= dk:
                continue
            # A view's own match that the pair drops must be off the prediction (its ray misses it).
            keep_ok = True
            for v in range(2):
                if matched[v][i] and np.linalg.norm(dv[v][pairs[k, v]] - out[v][i]) > 0.5:
                    keep_ok &= dk < ratio * _ray_distance(cameras[v], out[v][i], pred[i])
            if keep_ok and (best is None or dk < best[0]):
                best = (dk, i, k)
        if best is None:
            break
        _, i, k = best
        for v in range(2):
            new = dv[v][pairs[k, v]]
            if not np.allclose(new, out[v][i]):
                out[v][i], grown[v, i] = new, True
        seeds[i] = True
        X[i] = PX[k]
    return out, grown


def check_first_frame(inits: list[np.ndarray], dots: list[np.ndarray],
                      cameras: tuple[PinholeCamera, PinholeCamera], max_gap: float,
                      model_points=None, grow: bool = True, names=None, covariance=None,
                      one_view: int | None = None, confirm: int = 6) -> tuple[list[np.ndarray], np.ndarray]:
    """The first frame's matches checked between the views, against the 3-D layout, and grown.

    A marker matched in both views whose rays pass farther apart than ``max_gap`` is dropped in
    both. With ``model_points``, the matches are checked against the 3-D layout
    (:func:`~lipgen.recon.firstframe.check_layout`), and with ``grow`` then grown from those
    matched in both views (:func:`grow_first_frame`) and checked again.

    Parameters
    ----------
    inits : (virtual, real) (P, 2) float
        Each view's 2-D matches, NaN where unmatched.
    dots : (virtual, real) (m, 2), (n, 2) float
        All dots found in each view's first frame.
    cameras : (virtual, real) PinholeCamera
    max_gap : float
        Largest ray gap of a pair, mm.
    model_points : (P, 3) float or None
        The markers at rest in the frame of ``cameras``, mm.
    grow : bool
        Grow the matches.
    names : sequence of str, optional
        Marker names, for the log.
    covariance : (3P, 3P) float, optional
        The layout check's physics prior (:func:`~lipgen.recon.firstframe.check_layout`).
    one_view : int or None
        With ``model_points`` and ``grow``: when fewer than this many markers are left matched in
        both views after the ray-gap check, the first frame is seeded from one view instead
        (:func:`lipgen.recon.seedview.seed_from_one_view`, on the matches before the check), if
        that gives more markers matched in both views and leaves the pairs the views agree on
        where they are (:func:`lipgen.recon.seedview.moves_pairs`). None: never.
    confirm : int
        The seeding is taken only when, after the layout check and the growth, it leaves at least
        this many markers matched in both views, and more than the matches from the ray-gap check
        leave after the same steps. Right seeds place the layout where the other markers' dots are
        and the growth finds them; seeds on wrong dots find none (``hard`` 48: 3 wrong seeds grew
        to 3 pairs, ``hard`` 47: 3 right seeds grew to 8).

    Returns
    -------
    inits : (virtual, real) (P, 2) float
        The checked matches.
    bad : (P,) bool
        The markers dropped for their ray gap.
    """
    inits = [np.array(u, dtype=float) for u in inits]
    given = [u.copy() for u in inits]
    both = paired_markers(inits)
    gap = np.full(len(both), np.nan)
    if both.any():
        gap[both] = triangulate(cameras[1], inits[1][both], cameras[0], inits[0][both])[1]
    bad = both & (gap > max_gap)
    if bad.any():
        log.info("first frame: %d marker match(es) inconsistent between the views dropped", int(bad.sum()))
        inits[0][bad] = inits[1][bad] = np.nan
    if model_points is None:
        return inits, bad
    pairs = both & ~bad
    if grow and one_view is not None and pairs.sum() < one_view:
        seeded, view = seed_from_one_view(given, dots, cameras, model_points, max_gap)
        paired = paired_markers(seeded)
        if view is not None and paired.sum() > pairs.sum() and not moves_pairs(seeded, inits, pairs):
            kept = _settle(inits, dots, cameras, model_points, max_gap, covariance, names)
            held = np.all(np.isfinite(seeded[0]), axis=1) | np.all(np.isfinite(seeded[1]), axis=1)
            tried = _settle(seeded, dots, cameras, model_points, max_gap, covariance, names)
            n_kept, n_tried = int(paired_markers(kept).sum()), int(paired_markers(tried).sum())
            if n_tried >= confirm and n_tried > n_kept:
                log.info("first frame: %d marker(s) matched in both views, seeded from the %s view's matches "
                         "instead: %d, grown to %d (against %d)", int(pairs.sum()), VIEWS[view],
                         int(paired.sum()), n_tried, n_kept)
                return tried, bad & ~held     # a match kept is not a contradicted one
            log.info("first frame: the seeding from the %s view not taken: it grew to %d marker(s) matched "
                     "in both views (needs %d and more than %d)", VIEWS[view], n_tried, confirm, n_kept)
            return kept, bad
    return _settle(inits, dots, cameras, model_points, max_gap, covariance, names, grow), bad


def paired_markers(inits) -> np.ndarray:
    """(P,) bool: the markers matched in both views; ``inits`` is (virtual, real), each (P, 2) px
    with NaN rows for no match."""
    return np.all(np.isfinite(inits[0]), axis=1) & np.all(np.isfinite(inits[1]), axis=1)


def _settle(inits, dots, cameras, model_points, max_gap, covariance, names, grow: bool = True
            ) -> list[np.ndarray]:
    """The matches checked against the 3-D layout and, with ``grow``, grown and checked again."""
    def label(moved):
        return ", ".join(f"{VIEWS[v]} {i if names is None else names[i]}"
                         for v, i in zip(*np.nonzero(moved), strict=True))

    inits, moved = check_layout(inits, dots, cameras, model_points, max_gap, covariance=covariance)
    if moved.any():
        log.info("first frame: %d match(es) out of place in the 3-D layout changed or dropped (%s)",
                 int(moved.sum()), label(moved))
    if grow:
        inits, grown = grow_first_frame(inits, dots, cameras, model_points, max_gap)
        if grown.any():
            log.info("first frame: %d match(es) grown from the markers matched in both views (%s)",
                     int(grown.sum()), label(grown))
            inits, moved = check_layout(inits, dots, cameras, model_points, max_gap, covariance=covariance)
            if moved.any():
                log.info("first frame: %d grown match(es) out of place changed or dropped (%s)",
                         int(moved.sum()), label(moved))
    return inits
