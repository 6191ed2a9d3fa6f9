"""The nose mark where the tracker lost it: a stereo search along the clip, and a stand-in as the last resort.

The nose mark is the head's one fixed point, the translation the normalisation starts from
(:mod:`lipgen.recon.headpose`). The tracker finds it like any marker, from the layout at rest, but the
lip markers' offsets that place a lost lip marker do not reach it: it lies 37 mm from the lips. On
``hard`` 111 the direct view's first frame took a shading spot on the nose's outline 12 px from the
layout's guess, the two rays missed, and neither view held the mark in any frame after: the
reconstruction stopped with "the nose mark was never seen in both views" (as on ``hard`` 56, 58, 64
and 104 before), with the lips tracked.

:func:`search_nose` looks for the mark again where it lacks a pair:

* the lip markers seen in both views place the model's layout by a similarity, which puts the nose
  within 3.2-7.8 mm of the truth (median per set; at most 10.9 mm) on 19 development sets: the lips
  deform, and a subject's nose is not the model's;
* each view's dots near that place are paired with the other view's (rays within the clip's limit)
  into 3-D candidates within ``radius`` mm of it;
* one candidate per frame, or none, is chosen along the clip by dynamic programming: near the
  prediction (sd ``prior_sd``) and moving little between frames (sd ``step_sd``; the true nose moves
  0.5-1.4 mm per frame, at most 2.0, on the same sets), through the frames where the nose is held.
  A mark fixed on the head keeps a smooth path; spots of shading and chance pairs do not.

:func:`carried_nose` is the stand-in where no frame has the mark: the model's nose carried by the
lip markers' similarity. The lips then carry the head's translation, and the reconstruction says so.
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from lipgen.recon.association import LOST, RECOVERED
from lipgen.recon.dots import DotSettings, detect_dots
from lipgen.recon.similarity import umeyama
from lipgen.recon.tracks import Tracks
from lipgen.rig.pinhole import triangulate

__all__ = ["NoseNeverSeen", "predict_nose", "nose_candidates", "choose_path", "search_nose", "carried_nose",
           "settle_nose", "nose_line"]

log = logging.getLogger(__name__)

MIN_LIP_MARKERS = 4
"""Least lip markers seen in both views that place the layout (a similarity: 7 parameters)."""


class NoseNeverSeen(ValueError):
    """No frame has the nose mark, nor enough lip markers to carry the model's (:func:`carried_nose`)."""


def predict_nose(points: np.ndarray, visible: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """Where the model's layout, moved onto each frame's lip markers, puts the nose.

    Parameters
    ----------
    points : (F, P, 3) float
        The lip markers, mm (used where ``visible``).
    visible : (F, P) bool
    rest : (P + 1, 3) float
        The model's markers and its nose (last), mm.

    Returns
    -------
    (F, 3) float
        NaN in frames with fewer than :data:`MIN_LIP_MARKERS` visible markers.
    """
    out = np.full((len(points), 3), np.nan)
    for f in range(len(points)):
        use = visible[f] & np.all(np.isfinite(points[f]), axis=1)
        if use.sum() >= MIN_LIP_MARKERS:
            out[f] = umeyama(rest[:-1][use], points[f][use]).apply(rest[-1][None])[0]
    return out


def nose_candidates(views, cameras, guess: np.ndarray, radius: float, max_gap: float,
                    dots: DotSettings) -> tuple[np.ndarray, np.ndarray]:
    """One frame's stereo candidates for the nose: pairs of dots whose rays pass within ``max_gap``.

    Parameters
    ----------
    views : (virtual, real) images
    cameras : (virtual, real) PinholeCamera
    guess : (3,) float
        The predicted nose, mm.
    radius : float
        Candidates lie within this distance of ``guess``, mm.
    max_gap : float
        Largest ray gap of a pair, mm.
    dots : DotSettings
        The detector (searched in a window around the guess's projection in each view).

    Returns
    -------
    X : (k, 3) float
        The candidates' points, mm.
    uv : (k, 2, 2) float
        Their dots in the (virtual, real) views, px.
    """
    found = []
    for img, cam in zip(views, cameras, strict=True):
        img = np.asarray(img)
        c = cam.project(guess[None])[0]
        # The window: the projection of the search ball, with a margin for the detector's filters.
        reach = np.max(np.linalg.norm(cam.project(guess + radius * np.eye(3)) - c, axis=1)) + 4 * dots.sigma
        h, w = img.shape[:2]
        lo = np.clip(np.floor(c - reach).astype(int), 0, [w, h])
        hi = np.clip(np.ceil(c + reach).astype(int) + 1, 0, [w, h])
        if np.any(hi - lo < 4 * dots.sigma):
            return np.zeros((0, 3)), np.zeros((0, 2, 2))
        uv, _ = detect_dots(img[lo[1]:hi[1], lo[0]:hi[0]], dots)
        found.append(uv + lo)
    a, b = np.meshgrid(np.arange(len(found[0])), np.arange(len(found[1])), indexing="ij")
    a, b = a.ravel(), b.ravel()
    if len(a) == 0:
        return np.zeros((0, 3)), np.zeros((0, 2, 2))
    X, gap = triangulate(cameras[1], found[1][b], cameras[0], found[0][a])
    keep = (gap <= max_gap) & (np.linalg.norm(X - guess, axis=1) <= radius)
    return X[keep], np.stack([found[0][a[keep]], found[1][b[keep]]], axis=1)


def choose_path(candidates: list[np.ndarray], guess: np.ndarray, held: np.ndarray, prior_sd: float,
                step_sd: float, radius: float, max_bend: float = 1.0, min_run: int = 3) -> np.ndarray:
    """One candidate per frame, or none, with the least cost along the clip (Viterbi).

    Cost: ``0.5 (d / prior_sd)^2`` for a candidate ``d`` mm from the frame's guess, as much as a
    candidate at ``radius`` for none; ``0.5 (s / step_sd)^2`` for a step of ``s`` mm between the
    candidates of consecutive frames, and a 2-sd step to or from none. A frame where the nose is
    held (``held``) has its one candidate, at no cost, and must take it. Then a chosen candidate is
    dropped where it lies more than ``max_bend`` mm off the midpoint of its chosen neighbours (the
    true nose's second difference stays under 0.2 mm on the development sets, while a chance pair
    that bridges a frame the mark was missed in sits millimetres off), and so are the candidates in
    runs of fewer than ``min_run`` chosen frames (held ones included).

    Parameters
    ----------
    candidates : list of F (k_f, 3) float
        Each frame's candidates, mm (the held point where ``held``).
    guess : (F, 3) float
        Each frame's predicted nose (NaN: none; its candidates cost as much as none).
    held : (F,) bool
    prior_sd, step_sd, radius, max_bend : float
        mm.
    min_run : int

    Returns
    -------
    (F,) int
        The chosen candidate per frame, -1 for none.
    """
    none_cost, switch = 0.5 * (radius / prior_sd) ** 2, 2.0
    F = len(candidates)
    cost = [None] * F
    back = [None] * F
    prev = None
    for f, X in enumerate(candidates):
        X = np.asarray(X, float).reshape(-1, 3)
        if held[f]:
            emit = np.zeros(len(X))
        elif np.all(np.isfinite(guess[f])):
            emit = 0.5 * (np.linalg.norm(X - guess[f], axis=1) / prior_sd) ** 2
        else:
            emit = np.full(len(X), none_cost)
        emit = np.append(emit, np.inf if held[f] else none_cost)   # the last state is "none"
        if prev is None:
            cost[f], back[f] = emit, np.full(len(emit), -1)
        else:
            trans = np.full((len(prev) + 1, len(X) + 1), switch)
            trans[-1, -1] = 0.0
            if len(prev) and len(X):
                trans[:-1, :-1] = 0.5 * (np.linalg.norm(prev[:, None] - X[None], axis=2) / step_sd) ** 2
            total = cost[f - 1][:, None] + trans
            back[f] = np.argmin(total, axis=0)
            cost[f] = total[back[f], np.arange(len(X) + 1)] + emit
        prev = X
    path = np.full(F, -1)
    if F == 0:
        return path
    state = int(np.argmin(cost[-1]))
    for f in range(F - 1, -1, -1):
        n = len(cost[f]) - 1
        path[f] = -1 if state == n else state
        state = int(back[f][state])
    return _smooth_runs(path, candidates, held, max_bend, min_run)


def _smooth_runs(path: np.ndarray, candidates, held: np.ndarray, max_bend: float, min_run: int) -> np.ndarray:
    """``path`` without the bends and the short runs of :func:`choose_path`."""
    path = path.copy()
    X = np.full((len(path), 3), np.nan)
    for f in np.flatnonzero(path >= 0):
        X[f] = np.asarray(candidates[f], float).reshape(-1, 3)[path[f]]
    while True:
        # One wrong point bends its neighbours' midpoints by half as much: drop the worst bend first.
        bend = np.zeros(len(path))
        bend[1:-1] = np.nan_to_num(np.linalg.norm(X[1:-1] - 0.5 * (X[:-2] + X[2:]), axis=1))  # run ends: 0
        bend[held] = 0.0
        near = np.maximum(np.r_[0.0, bend[:-1]], np.r_[bend[1:], 0.0])
        worst = (bend > max_bend) & (bend >= near)
        if not worst.any():
            break
        path[worst], X[worst] = -1, np.nan
    chosen = np.concatenate([[False], path >= 0, [False]])
    edges = np.flatnonzero(np.diff(chosen.astype(np.int8)))
    for start, stop in zip(edges[::2], edges[1::2], strict=True):
        if stop - start < min_run:
            path[start:stop][~held[start:stop]] = -1
    return path


def search_nose(frame_views, tracks: tuple[Tracks, Tracks], points: np.ndarray, visible: np.ndarray,
                cameras, rest: np.ndarray, max_gap: float, dots: DotSettings, floor: float,
                radius: float = 12.0, prior_sd: float = 5.0, step_sd: float = 2.0
                ) -> tuple[tuple[Tracks, Tracks], np.ndarray]:
    """The nose found again where it lacks a pair (see the module docstring).

    Parameters
    ----------
    frame_views : callable
        ``frame_views(f)`` -> frame f's (virtual, real) views.
    tracks : (virtual, real) Tracks
        The tracker's, with the nose as the last mark (P + 1 marks).
    points : (F, P + 1, 3) float
        Their triangulated points, mm, and ``visible (F, P + 1)`` where the pair is within the limit.
    cameras : (virtual, real) PinholeCamera
    rest : (P + 1, 3) float
        The model's markers and nose at rest, in the frame of ``cameras``, mm.
    max_gap : float
        The clip's ray-gap limit, mm.
    dots : DotSettings
        The tracker's detector; searched at ``floor`` (its least contrast floor).
    radius, prior_sd, step_sd : float
        mm (:func:`choose_path`).

    Returns
    -------
    (virtual, real) : Tracks
        Copies with the nose's found pairs (status ``RECOVERED``), where it had none.
    found : (F,) bool
        The frames given a pair.
    """
    F = len(visible)
    held = visible[:, -1].copy()
    guess = predict_nose(points[:, :-1], visible[:, :-1], rest)
    detector = replace(dots, min_contrast=min(floor, dots.min_contrast))
    cands, pairs = [], []
    for f in range(F):
        if held[f]:
            cands.append(points[f, -1][None])
            pairs.append(None)
        elif np.all(np.isfinite(guess[f])):
            X, uv = nose_candidates(frame_views(f), cameras, guess[f], radius, max_gap, detector)
            cands.append(X)
            pairs.append(uv)
        else:
            cands.append(np.zeros((0, 3)))
            pairs.append(None)
    path = choose_path(cands, guess, held, prior_sd, step_sd, radius)
    found = ~held & (path >= 0)
    out = []
    for v, t in enumerate(tracks):
        uv, status, score = t.uv.copy(), t.status.copy(), t.score.copy()
        rejected = np.zeros(status.shape, bool) if t.rejected is None else t.rejected.copy()
        for f in np.flatnonzero(found):
            uv[f, -1] = pairs[f][path[f], v]
        status[found, -1], score[found, -1], rejected[found, -1] = RECOVERED, np.nan, False
        out.append(Tracks(uv=uv, visible=status != LOST, status=status, score=score, rejected=rejected))
    return (out[0], out[1]), found


def carried_nose(points: np.ndarray, visible: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """The model's nose carried by each frame's lip markers (a similarity), interpolated in time where
    too few are seen: the stand-in for a nose mark never seen in both views.

    Parameters
    ----------
    points : (F, P, 3) float
    visible : (F, P) bool
    rest : (P + 1, 3) float
        As :func:`predict_nose`.

    Returns
    -------
    (F, 3) float

    Raises
    ------
    NoseNeverSeen
        When no frame has :data:`MIN_LIP_MARKERS` lip markers seen.
    """
    nose = predict_nose(points, visible, rest)
    good = np.flatnonzero(np.all(np.isfinite(nose), axis=1))
    if len(good) == 0:
        raise NoseNeverSeen(f"no frame has {MIN_LIP_MARKERS} lip markers seen in both views to carry the "
                            "nose")
    for a in range(3):
        nose[:, a] = np.interp(np.arange(len(nose)), good, nose[good, a])
    return nose


def settle_nose(frame_views, tracks: tuple[Tracks, Tracks], points: np.ndarray, gap: np.ndarray,
                visible: np.ndarray, cameras, rest: np.ndarray, max_gap: float, dots: DotSettings,
                floor: float, search: bool = True):
    """The nose for the normalisation: searched for where it lacks a pair (with ``search``,
    :func:`search_nose`), and where no frame has it, the stand-in (:func:`carried_nose`).

    Parameters
    ----------
    frame_views, tracks, cameras, rest, max_gap, dots, floor
        As :func:`search_nose`.
    points : (F, P + 1, 3) float
    gap : (F, P + 1) float
    visible : (F, P + 1) bool
        The triangulation of ``tracks`` within ``max_gap``
        (:func:`lipgen.recon.steps.triangulate_within_limit`).
    search : bool

    Returns
    -------
    tracks, points, gap, visible
        Copies, with the found pairs; where the stand-in is used it fills ``points[:, -1]`` while
        ``visible[:, -1]`` stays False.
    record : dict
        ``searched`` (frames without a pair), ``found`` (given one) and ``stand_in`` (bool).

    Raises
    ------
    NoseNeverSeen
        When the stand-in is needed and no frame has enough lip markers to carry it.
    """
    points, gap, visible = points.copy(), gap.copy(), visible.copy()
    record = {"searched": 0, "found": 0, "stand_in": False}
    if search and not visible[:, -1].all():
        tracks, found = search_nose(frame_views, tracks, points, visible, cameras, rest, max_gap, dots, floor)
        record.update(searched=int((~visible[:, -1]).sum()), found=int(found.sum()))
        if found.any():
            log.info("nose mark found again in %d of the %d frame(s) it lacked a pair in", record["found"],
                     record["searched"])
            X, g = triangulate(cameras[1], tracks[1].uv[found, -1], cameras[0], tracks[0].uv[found, -1])
            points[found, -1], gap[found, -1], visible[found, -1] = X, g, True
    if not visible[:, -1].any():
        points[:, -1] = carried_nose(points[:, :-1], visible[:, :-1], rest)
        record["stand_in"] = True
        log.warning("the nose mark was never seen in both views: the model's nose is carried by the lip "
                    "markers, so the head's translation includes the lips' own (info['nose'])")
    return tracks, points, gap, visible, record


def nose_line(record: dict | None) -> str | None:
    """One sentence on what :func:`settle_nose` did, for the command's output and the report; None when
    the tracker held the nose in every frame (or the reconstruction predates the search)."""
    if not record or (not record.get("searched") and not record.get("stand_in")):
        return None
    if record["stand_in"]:
        return ("The nose mark was never seen in both views: the model's nose was carried by the lip "
                "markers, so the head's translation includes the lips' own (check the nose mark's ink and "
                "lighting).")
    return (f"The nose mark lacked a pair in {record['searched']} frame(s); found again, from where the lip "
            f"markers place it, in {record['found']}" + ("." if record["found"] == record["searched"]
                                                          else "; interpolated in the others."))
