"""Tracking a marker back from the frame it was first seen in, to the frames before it.

A marker the first frame does not match (its dot beside a lure, or its match taken back) is
acquired on a later frame (:func:`lipgen.recon.acquire.acquire_layout`, confirmed by the other
view). Acquisition is strict, since a wrong dot taken then would be followed: on the demo's
``easy`` clip the direct view's ``lower_right`` first passes it at frame 7, so frames 1-6 were
lost (98.9 % accepted instead of 99.1 %). Once the marker is known, its earlier frames are no
longer a search: :func:`backfill` walks back from its first sighting one frame at a time. It
predicts the marker from its position in the later frame moved as its tracked neighbours moved
(Gaussian weights by layout distance), takes the nearest free dot of that frame (the tracker's
own round dots, :attr:`lipgen.recon.track.MarkerTracker.dot_history`) within the acquisition
gate, when it is unambiguous, about as dark as the marker's dot, and confirmed by the other view:
the two rays meet (the sequence's ray-gap limit) and the 3-D point does not jump from the later
frame's (:class:`lipgen.recon.jumps.StepLimit`; a marker with too few accepted steps of its own
gets the limit of all markers' steps pooled, since a lure along the epipolar line passes the ray
gap and only its depth gives it away). A marker new in both views is walked back in both
together. The walk stops at the first frame without a confirmed dot (``max_misses``: after that many
frames in a row; a step over a missed frame is checked against the limit times the square root
of the frames elapsed, which a lure close along the epipolar line can pass).
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen.recon.jumps import StepLimit
from lipgen.recon.pointreg import layout_spacing
from lipgen.recon.track import LOST, RECOVERED, MarkerTracker
from lipgen.rig.camera import VIEWS
from lipgen.rig.pinhole import triangulate

__all__ = ["WalkQueue", "backfill", "rewalk", "walk_back", "neighbour_motion", "nearest_free_dot"]

log = logging.getLogger(__name__)


def neighbour_motion(reference: np.ndarray, uv_from: np.ndarray, uv_to: np.ndarray, ok: np.ndarray,
                     i: int, width: float | None = None) -> np.ndarray | None:
    """How marker ``i``'s neighbours moved between two frames: their Gaussian-weighted mean offset.

    Parameters
    ----------
    reference : (P, 2) float
        The layout; weights fall off with distance in it (width: the median distance from a
        marker to its nearest neighbour).
    uv_from, uv_to : (P, 2) float
        Marker positions in the two frames, pixels.
    ok : (P,) bool
        Markers seen in both frames (``i`` itself is left out).
    i : int
        The marker.
    width : float, optional
        :func:`~lipgen.recon.pointreg.layout_spacing` of ``reference``, if the caller has it.

    Returns
    -------
    (2,) float or None
        The weighted mean of ``uv_to - uv_from`` over the neighbours; None when none is seen.
    """
    got = neighbour_moves(reference, uv_from, uv_to, ok, i, width)
    return None if got is None else got[0]


def neighbour_moves(reference: np.ndarray, uv_from: np.ndarray, uv_to: np.ndarray, ok: np.ndarray,
                    i: int, width: float | None = None) -> tuple[np.ndarray, float] | None:
    """:func:`neighbour_motion`'s mean move ``(2,)`` and the weighted RMS spread (px) of the neighbours' own
    moves about it: how far they disagree on where ``i`` goes. None when no neighbour is seen."""
    ok = np.asarray(ok, dtype=bool).copy()
    ok[i] = False
    if not ok.any():
        return None
    if width is None:
        width = layout_spacing(reference)
    w = np.exp(-0.5 * (np.linalg.norm(reference[ok] - reference[i], axis=1) / width) ** 2)
    if w.sum() <= 1e-12:
        return None
    moves = uv_to[ok] - uv_from[ok]
    mean = (w @ moves) / w.sum()
    return mean, float(np.sqrt((w @ np.sum((moves - mean) ** 2, axis=1)) / w.sum()))


def nearest_free_dot(dots: np.ndarray, pred: np.ndarray, taken: np.ndarray, gate: float, ratio: float,
                     held: float, usable: np.ndarray | None = None,
                     rivals: np.ndarray | None = None) -> int | None:
    """The index of the dot nearest ``pred`` within ``gate`` that no other marker holds, if unambiguous.

    Parameters
    ----------
    dots : (k, 2) float
        Candidate dots, pixels.
    pred : (2,) float
        Where the marker is predicted.
    taken : (m, 2) float
        Other markers' sightings: a dot within ``held`` pixels of one is held.
    gate, ratio, held : float
        Pixels; the unambiguity ratio; pixels.
    usable : (k,) bool, optional
        Dots that may be taken at all (e.g. dark enough).
    rivals : (n, 2) float, optional
        Positions the dot must be nearer ``pred`` than ``1 / ratio`` times; default ``taken``.

    Returns
    -------
    int or None
        None where no free dot lies within ``gate``, or another dot, or a rival, is nearly as near.
    """
    rivals = taken if rivals is None else rivals
    free = np.ones(len(dots), dtype=bool) if usable is None else np.asarray(usable, dtype=bool).copy()
    if len(taken):
        free &= np.linalg.norm(dots[:, None] - taken[None], axis=2).min(1) >= held
    r = np.linalg.norm(dots - pred, axis=1)
    if not free.any():
        return None
    j = int(np.argmin(np.where(free, r, np.inf)))
    if r[j] > gate:
        return None
    rest = np.delete(r, j)
    if len(rest) and r[j] >= ratio * rest.min():       # another dot nearly as near
        return None
    if len(rivals) and r[j] >= ratio * np.linalg.norm(rivals - dots[j], axis=1).min():
        return None
    return j


def _candidate(tracker: MarkerTracker, t: int, i: int, pred: np.ndarray, gate: float) -> np.ndarray | None:
    """The free, dark, unambiguous dot of frame ``t`` nearest ``pred`` within ``gate``, or None."""
    cfg = tracker.cfg
    hist = tracker.dot_history[t]
    if hist is None or len(hist[0]) == 0:
        return None
    dots, strength = hist
    uv, status, _ = tracker._out[t]
    taken = uv[(status != LOST) & (np.arange(len(uv)) != i)]
    usable = None
    if np.isfinite(tracker.strength[i]):
        usable = strength >= cfg.min_strength_ratio * tracker.strength[i]
    j = nearest_free_dot(dots, pred, taken, gate, cfg.acquire_ratio, cfg.dots.separation / 2, usable)
    return None if j is None else dots[j]


class WalkQueue:
    """Walks back made once the marker has stood in both views for a few frames.

    A marker first seen in a view (:func:`backfill`'s walk) or found again (:func:`rewalk`'s) on
    a wrong pair of dots that both views confirm would carry the wrong dots back through the
    frames before. Such a sighting is mostly taken back within a frame or two (a ray gap, a 3-D
    jump), so the walk from frame ``k`` is made only once the marker has been seen in both views
    in every frame from ``k`` to ``k + frames - 1``, and dropped if it is not.

    Parameters
    ----------
    n_markers : int
        Number of markers P.
    frames : int
        Frames in a row, from the walk's start, the marker must be seen in both views.
    same : float
        As in :func:`rewalk`.
    """

    def __init__(self, n_markers: int, frames: int = 3, same: float = 1.0):
        if int(frames) < 1:
            raise ValueError(f"frames must be at least 1, got {frames!r}")
        self.frames, self.same = int(frames), float(same)
        self.start = np.full((2, int(n_markers)), -1, dtype=np.int64)   # (first sighting, found again)
        self.views = np.zeros((2, int(n_markers)), dtype=bool)           # views new at the first sighting
        self.filled = np.zeros((2, int(n_markers)), dtype=np.int64)
        self.replaced = np.zeros((2, int(n_markers)), dtype=np.int64)

    def step(self, trackers: list[MarkerTracker], cameras, new: np.ndarray, gap_limit: float,
             steps: StepLimit | None = None, again: bool = True, names=None) -> None:
        """Queue this image's walks and make those now due.

        Parameters
        ----------
        trackers : (virtual, real) MarkerTracker
            After the current image's step and view checks.
        cameras : (virtual, real) PinholeCamera
        new : (2, P) bool
            Markers seen in this image for the first time, per view.
        gap_limit : float
            Largest distance between the two rays, mm.
        steps : StepLimit, optional
        again : bool
            Also walk back markers found again (:func:`rewalk`).
        names : sequence of str, optional
        """
        k = len(trackers[0]._out) - 1
        st = [tr._out[k][1] for tr in trackers]
        both = (st[0] != LOST) & (st[1] != LOST)
        self.start[:, ~both] = -1
        first = np.asarray(new, dtype=bool).any(0)
        add = first & both & (self.start[0] < 0)
        self.start[0, add], self.views[:, add] = k, np.asarray(new, dtype=bool)[:, add]
        if again:
            found = ((st[0] == RECOVERED) | (st[1] == RECOVERED) | trackers[0].reacquired
                     | trackers[1].reacquired)
            add = found & both & ~first & (self.start[1] < 0) & (self.start[0] < 0)
            self.start[1, add] = k
        due = (self.start >= 0) & (k - self.start + 1 >= self.frames)
        if not due.any():
            return
        limits = None if steps is None else steps.limits(pooled=True)
        for q, i in zip(*np.nonzero(due), strict=True):
            views = tuple(np.flatnonzero(self.views[:, i])) if q == 0 else (0, 1)
            f, r = walk_back(trackers, cameras, i, views, int(self.start[q, i]), gap_limit, limits,
                             same=None if q == 0 else self.same)
            self.filled[:, i] += f
            self.replaced[:, i] += r
            if f.any():
                log.info("%s from frame %d: %s", "tracked back from the first sighting" if q == 0 else
                         "walked back from a sighting found again", self.start[q, i], ", ".join(
                             f"{VIEWS[v]} {i if names is None else names[i]} {f[v]} frame(s)"
                             + (f" ({r[v]} paired sighting(s) on another dot replaced)" if r[v] else "")
                             for v in range(2) if f[v]))
            self.start[q, i] = -1


def backfill(trackers: list[MarkerTracker], cameras, new: np.ndarray, gap_limit: float,
             steps: StepLimit | None = None, max_misses: int = 0, names=None) -> np.ndarray:
    """Fill the frames before each marker's first sighting in a view, walking back from it.

    Parameters
    ----------
    trackers : (virtual, real) MarkerTracker
        After the current image's step and view checks; their ``dot_history`` holds the
        earlier frames' dots.
    cameras : (virtual, real) PinholeCamera
    new : (2, P) bool
        Markers seen in the current image for the first time, per view.
    gap_limit : float
        Largest distance between the two rays, mm.
    steps : StepLimit, optional
        The 3-D step limits; without it, only the ray gap confirms.
    max_misses : int
        Frames in a row without a confirmed dot after which the walk stops.
    names : sequence of str, optional
        Marker names, for the log.

    Returns
    -------
    (2, P) int
        Frames filled per view and marker. The filled sightings are ``RECOVERED`` (and no longer
        counted as rejected) in the trackers' output.
    """
    new = np.asarray(new, dtype=bool)
    filled = np.zeros(new.shape, dtype=np.int64)
    k = len(trackers[0]._out) - 1
    limits = None if steps is None else steps.limits(pooled=True)
    for i in np.flatnonzero(new.any(0)):
        filled[:, i] = walk_back(trackers, cameras, i, [v for v in range(2) if new[v, i]], k, gap_limit,
                                 limits, max_misses)[0]
    if filled.any():
        log.info("tracked back from the first sighting: %s", ", ".join(
            f"{'virtual' if v == 0 else 'real'} {i if names is None else names[i]} {filled[v, i]} frame(s)"
            for v, i in zip(*np.nonzero(filled), strict=True)))
    return filled


def rewalk(trackers: list[MarkerTracker], cameras, skip: np.ndarray, gap_limit: float,
           steps: StepLimit | None = None, same: float = 1.0, names=None) -> tuple[np.ndarray, np.ndarray]:
    """Walk back the markers found again in the current image, in both views, until the history agrees.

    A marker re-acquired after a loss, or found from the motion prediction (``RECOVERED``), and
    seen in both views, is walked back (:func:`walk_back`) from the current image until the
    frame where both views already hold its walked dots (within ``same`` px): the frames it was
    lost in are filled, and sightings on another dot are replaced (a lure the marker followed
    before it was lost, which the later track contradicts).

    Parameters
    ----------
    trackers : (virtual, real) MarkerTracker
        After the current image's step and view checks.
    cameras : (virtual, real) PinholeCamera
    skip : (P,) bool
        Markers not to walk (e.g. those :func:`backfill` walks).
    gap_limit : float
        Largest distance between the two rays, mm.
    steps : StepLimit, optional
    same : float
        Pixels within which a held sighting is the walk's dot.
    names : sequence of str, optional

    Returns
    -------
    filled, replaced : (2, P) int
        Frames written per view and marker, and of them those that replaced a pair's dot.
    """
    k = len(trackers[0]._out) - 1
    st = [tr._out[k][1] for tr in trackers]
    found = (st[0] == RECOVERED) | (st[1] == RECOVERED) | trackers[0].reacquired | trackers[1].reacquired
    walk = found & (st[0] != LOST) & (st[1] != LOST) & ~np.asarray(skip, dtype=bool)
    P = len(st[0])
    filled, replaced = np.zeros((2, P), dtype=np.int64), np.zeros((2, P), dtype=np.int64)
    if k == 0 or not walk.any():
        return filled, replaced
    limits = None if steps is None else steps.limits(pooled=True)
    for i in np.flatnonzero(walk):
        filled[:, i], replaced[:, i] = walk_back(trackers, cameras, i, (0, 1), k, gap_limit, limits,
                                                 same=same)
    if replaced.any():
        log.info("frame %d, walked back: %s", k, ", ".join(
            f"{VIEWS[v]} {i if names is None else names[i]} {filled[v, i]} frame(s), {replaced[v, i]} "
            "paired sighting(s) on another dot replaced" for v, i in zip(*np.nonzero(filled), strict=True)))
    return filled, replaced


def walk_back(trackers: list[MarkerTracker], cameras, i: int, views, k: int, gap_limit: float,
              limits: np.ndarray | None = None, max_misses: int = 0,
              same: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Track marker ``i`` back from frame ``k`` in ``views``, each frame confirmed by the other view.

    Parameters
    ----------
    trackers : (virtual, real) MarkerTracker
    cameras : (virtual, real) PinholeCamera
    i : int
        The marker.
    views : sequence of int
        The views walked back (0, 1 or both); a view not walked gives its own sightings as they are.
    k : int
        The frame the walk starts from: the marker's sightings there are taken as right.
    gap_limit : float
        Largest distance between the two rays, mm.
    limits : (P,) float, optional
        Step limits, mm per frame (``StepLimit.limits(pooled=True)``); None: the ray gap alone confirms.
    max_misses : int
        Frames in a row without a confirmed dot after which the walk stops.
    same : float, optional
        The walk stops at the first frame where every walked view already holds a sighting
        within ``same`` pixels of the walk's dot (the history agrees from there on).

    Returns
    -------
    filled : (2,) int
        Frames written per view. A written sighting is ``RECOVERED`` and not counted as
        rejected; whatever the view held there before (nothing, or another dot) is replaced.
    replaced : (2,) int
        Of them, sightings that replaced another dot where both views held the marker (a pair
        the ray gap had let through).
    """
    filled = np.zeros(2, dtype=np.int64)
    replaced = np.zeros(2, dtype=np.int64)
    cur = {v: trackers[v]._out[k][0][i].copy() for v in range(2)}
    ref_t = {v: k for v in range(2)}
    pt = _point(cameras, cur[0], cur[1])
    pt_t, misses = k, 0
    width = {v: layout_spacing(trackers[v].reference) for v in views}
    for t in range(k - 1, -1, -1):
        if misses > max_misses:
            break
        cand = {}
        for v in range(2):
            uv_t, st_t, _ = trackers[v]._out[t]
            if v not in views:
                if st_t[i] != LOST:
                    cand[v] = uv_t[i]
                continue
            if t >= len(trackers[v].dot_history):
                continue
            uv_r, st_r, _ = trackers[v]._out[ref_t[v]]
            move = neighbour_motion(trackers[v].reference, uv_r, uv_t, (st_r != LOST) & (st_t != LOST), i,
                                    width[v])
            if move is None:
                continue
            gate = trackers[v].cfg.acquire_gate or trackers[v].cfg.recovery_gate
            c = _candidate(trackers[v], t, i, cur[v] + move, gate)
            if c is not None:
                cand[v] = c
        ok = len(cand) == 2 and any(v in cand for v in views)
        if ok:
            x, gap = triangulate(cameras[1], cand[1][None], cameras[0], cand[0][None])
            ok = float(gap[0]) <= gap_limit
            if ok and limits is not None and np.all(np.isfinite(pt)):
                ok = np.linalg.norm(x[0] - pt) / np.sqrt(pt_t - t) <= limits[i]
        if not ok:
            misses += 1
            continue
        misses = 0
        pt, pt_t = x[0], t
        held = [trackers[v]._out[t][1][i] != LOST for v in range(2)]
        agree = [held[v] and np.linalg.norm(trackers[v]._out[t][0][i] - cand[v]) <= (same or 0.0)
                 for v in range(2)]
        if same is not None and all(agree[v] for v in views):
            break
        for v in views:
            cur[v], ref_t[v] = cand[v].copy(), t
            if agree[v]:
                continue
            uv_t, st_t, _ = trackers[v]._out[t]
            replaced[v] += held[0] and held[1]
            uv_t[i], st_t[i] = cand[v], RECOVERED
            trackers[v]._rejected[t][i] = False
            filled[v] += 1
    return filled, replaced


def _point(cameras, uv0: np.ndarray, uv1: np.ndarray) -> np.ndarray:
    """(3,) the ray-midpoint of one marker's two sightings; NaN if a view has none."""
    if not (np.all(np.isfinite(uv0)) and np.all(np.isfinite(uv1))):
        return np.full(3, np.nan)
    return triangulate(cameras[1], uv1[None], cameras[0], uv0[None])[0][0]
