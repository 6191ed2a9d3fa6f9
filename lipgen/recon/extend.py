"""Accepted tracks walked on, frame by frame, into the frames where the checks left the marker lost.

The checks after the tracking take sightings back and put nothing in their place: where two
markers held one dot in both views (:mod:`lipgen.recon.shareddot`) both are taken back for the
rest of that span, though one of them was on its own dot and the other's own dot was free (on
``hard`` 186, ``corner_left`` and ``lower_corner_left`` from frame 5 to the end, their dots
detected within 0.4 px in the direct view). And a marker lost for longer than the gap fill's few
frames (:mod:`lipgen.recon.gapfill`) is not looked for again once the tracker has passed.

:func:`extend_tracks` starts from the end of each run of at least ``min_run`` accepted frames (the
pipeline's ``walk_frames``, 3: a label that held for a few frames, not a one-frame wrong pair) next to
a frame where the marker is not accepted, and walks into that frame, then the next, forward and
backward, as :func:`lipgen.recon.backfill.walk_back` walks inside the tracker. Starting only from
sightings both tracking runs agree on (:func:`lipgen.recon.crosscheck.runs_agree`), as the gap fill
does, left most walks unstarted on development (hard 174-188: +62 against +206 over five sets): the
two runs agree on 73 % of accepted sightings of ``hard`` 186, and not on its lost corners' last ones.

* in each view the marker is predicted where it was in the frame before, moved as its neighbours
  moved (:func:`lipgen.recon.backfill.neighbour_motion`, over markers accepted in both frames);
* the candidates are the detector's peaks at the tracker's least floor and the curvature
  detector's (as the gap fill's), less those within half the detector's separation of another
  marker's accepted sighting (a sighting the checks did not accept holds no dot: on ``hard`` 186 the
  mirror's ``lower_left``, rejected, sat on ``lower_corner_left``'s dot);
* the nearest within ``gate`` is taken when it is unambiguous: nearer than ``ratio`` times the
  next candidate, any other marker's accepted sighting, and any other walking marker's prediction (so two
  markers walking into a shared dot's frames cannot both claim it, and the one whose prediction
  sits on it takes it);
* both views' dots must be found and their rays meet within the ray-gap limit.

The walk stops at its first frame without such a pair, and where the marker is accepted again.
A walked sighting is ``RECOVERED``.

Measured (``renders/examples/tracking/w39.md``; score = accepted within 3 px - 10 x accepted over 3 px).
Held out, fresh ``hard`` 191-198: +337, no set down, accepted 89.4 -> 92.6 %, over 3 px 64 -> 65;
``default`` 180-181: +50, accepted 99.4 -> 99.9 %, none over 3 px. The known failure: a set whose labels
are mostly wrong from the first frame (development ``hard`` 181, 32.9 % accepted) has its wrong tracks
walked on too (-426, over 3 px 157 -> 207).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from lipgen.recon.association import LOST, RECOVERED
from lipgen.recon.backfill import nearest_free_dot, neighbour_motion
from lipgen.recon.dots import DotSettings, refine_centroids
from lipgen.recon.gapfill import view_peaks
from lipgen.recon.pointreg import layout_spacing
from lipgen.recon.tracks import Tracks
from lipgen.rig.pinhole import PinholeCamera, triangulate

__all__ = ["extend_tracks", "extend_line"]


def _check(F: int, P: int, accepted, start, reference, gate, ratio, min_run) -> None:
    if isinstance(min_run, bool) or int(min_run) != min_run or min_run < 1:
        raise ValueError(f"min_run must be a whole number of frames >= 1, got {min_run!r}")
    for name, mask in (("accepted", accepted), ("start", start)):
        if mask is not None and np.shape(mask) != (F, P):
            raise ValueError(f"{name} must have shape {(F, P)} (frames, markers), got {np.shape(mask)}")
    if np.shape(reference) != (2, P, 2):
        raise ValueError(f"reference must have shape {(2, P, 2)} (views, markers, uv), "
                         f"got {np.shape(reference)}")
    for name, value, hi in (("gate", gate, np.inf), ("ratio", ratio, 1.0)):
        number = isinstance(value, int | float | np.floating) and not isinstance(value, bool)
        if not (number and np.isfinite(value) and 0 < value and value <= hi):
            raise ValueError(f"{name} must be a number in (0, {hi}], got {value!r}")


def extend_tracks(tracks: tuple[Tracks, Tracks], frame_at: Callable[[int], tuple],
                  cameras: tuple[PinholeCamera, PinholeCamera], accepted: np.ndarray, reference: np.ndarray,
                  dots: DotSettings, floor: float, max_gap: float, gate: float, ratio: float = 0.6,
                  start: np.ndarray | None = None, min_run: int = 1) -> tuple[tuple[Tracks, Tracks], dict]:
    """Walk accepted tracks on into the frames where they are not accepted (see the module docstring).

    Parameters
    ----------
    tracks : (virtual, real) Tracks
        F frames, P markers each.
    frame_at : callable
        ``frame_at(f)`` -> the (virtual, real) images of frame ``f``.
    cameras : (virtual, real) PinholeCamera
    accepted : (F, P) bool
        Markers accepted in both views (rays within ``max_gap``).
    reference : (2, P, 2) float
        The layout in each view (the markers at rest projected), pixels: the neighbours' weights.
    dots : DotSettings
        The tracker's detector.
    floor : float
        Least contrast of a detector peak (the tracker's least floor).
    max_gap : float
        The ray-gap limit, mm.
    gate : float
        Farthest a dot may lie from the prediction, pixels.
    ratio : float
        The unambiguity ratio.
    start : (F, P) bool, optional
        Accepted sightings a walk may start from; None: every accepted sighting.
    min_run : int
        A walk starts only from the end of at least this many accepted frames in a row.

    Returns
    -------
    (virtual, real) : Tracks
        Copies, with the walked sightings.
    record : dict
        ``walks`` (walks tried: a track's end next to a frame where the marker is not accepted) and
        ``walked`` (frame-marker pairs written).
    """
    F, P = tracks[0].uv.shape[:2]
    _check(F, P, accepted, start, reference, gate, ratio, min_run)
    ok = np.asarray(accepted, dtype=bool).copy()
    allowed = ok & (np.ones_like(ok) if start is None else np.asarray(start, dtype=bool))
    uv = [t.uv.copy() for t in tracks]
    status = [t.status.copy() for t in tracks]
    width = [layout_spacing(reference[v]) for v in range(2)]
    held_r = dots.separation / 2
    walks, walked = 0, 0
    for step in (1, -1):
        begin = _run_ends(ok, min_run, step) & allowed
        live = begin[0 if step == 1 else F - 1].copy()
        frames = range(1, F) if step == 1 else range(F - 2, -1, -1)
        for f in frames:
            prev = f - step
            walkers = np.flatnonzero(live & ~ok[f])
            live = begin[f].copy()
            if len(walkers) == 0:
                continue
            walks += int(np.sum(begin[prev, walkers]))
            # looked for afresh in each pass: keeping every walked frame's images for the other pass
            # would hold up to 2 F grey images
            peaks = [view_peaks(img, dots, floor) for img in frame_at(f)]
            both = ok[prev] & ok[f]
            pred = np.full((2, P, 2), np.nan)
            for v in range(2):
                for i in walkers:
                    move = neighbour_motion(reference[v], uv[v][prev], uv[v][f], both, i, width[v])
                    if move is not None:
                        pred[v, i] = uv[v][prev, i] + move
            for i in walkers:
                held = [np.where(ok[f][:, None], uv[v][f], np.nan) for v in range(2)]
                pair = [_pick(peaks[v], pred[v], held[v], i, gate, ratio, held_r, dots) for v in range(2)]
                if pair[0] is None or pair[1] is None:
                    continue
                if not triangulate(cameras[1], pair[1][None], cameras[0], pair[0][None])[1][0] <= max_gap:
                    continue
                for v in range(2):
                    uv[v][f, i], status[v][f, i] = pair[v], RECOVERED
                ok[f, i], live[i] = True, True
                walked += 1
    out = tuple(replace(t, uv=uv[v], status=status[v], visible=status[v] != LOST)
                for v, t in enumerate(tracks))
    return out, {"walks": walks, "walked": walked}


def _run_ends(ok: np.ndarray, n: int, step: int) -> np.ndarray:
    """(F, P) bool: the frames ending (walking the way ``step``) a run of at least ``n`` True in ``ok``."""
    out = ok.copy()
    for k in range(1, n):
        behind = np.zeros_like(ok)
        if step == 1:
            behind[k:] = ok[:-k]
        else:
            behind[:-k] = ok[k:]
        out &= behind
    return out


def _pick(found, pred, held_f, i, gate, ratio, held_r, dots) -> np.ndarray | None:
    """One view's dot for walker ``i``: the free, unambiguous candidate nearest its prediction, refined.
    ``held_f`` (P, 2): the sightings of the markers accepted (or walked) in this frame, NaN elsewhere."""
    cand, gray = found
    if not np.all(np.isfinite(pred[i])) or len(cand) == 0:
        return None
    others = np.delete(np.arange(len(held_f)), i)
    held = held_f[others][np.all(np.isfinite(held_f[others]), axis=1)]
    rivals = np.vstack([held, pred[others][np.all(np.isfinite(pred[others]), axis=1)]])
    j = nearest_free_dot(cand, pred[i], held, gate, ratio, held_r, rivals=rivals)
    if j is None:
        return None
    got = refine_centroids(gray, cand[j][None], dots.sigma, window=dots.window)[0]
    return got if np.linalg.norm(got - pred[i]) <= gate else None


def extend_line(record: dict | None) -> str | None:
    """One sentence on what :func:`extend_tracks` did, for the command's output and the report; None when it
    did not run."""
    if not record:
        return None
    return (f"Walked {record['walked']} marker sighting(s) on from accepted ones into frames where the "
            f"marker was lost, each a dot near where its neighbours' motion put it in both views.")
