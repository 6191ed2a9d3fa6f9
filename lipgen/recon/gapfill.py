"""Short gaps in a marker's accepted track, filled from both ends.

On ``hard`` frames a marker is often lost for one to three frames in the middle of a clip and
accepted on both sides: its dot was there, but blurred, defocused or faint in that frame, the
tracker's top-hat found no peak (on the development sets the curvature detector, which the
tracker uses only as a fallback, has one within 1.5 px in most of them) and the correlation step
gave up. Where a marker is accepted (both views, rays within the limit) in the frame before a gap
and in the frame after it, its identity is settled on both sides, and its image in each view moves
little between them: its position in a gap frame is interpolated, in each view, between the two
sightings that frame the gap. :func:`fill_short_gaps` looks there for a dot:

* candidates are the peaks of the detector at the tracker's least floor and of the curvature
  detector (:func:`lipgen.recon.blobs.blob_peaks`), not within half the detector's separation of
  another marker's sighting in that frame;
* the nearest candidate within the detector's separation of the interpolated position is
  refined (:func:`lipgen.recon.dots.refine_centroids`) and must stay within it;
* a view's own sighting in that frame stands if it is that near the interpolated position, else
  a candidate replaces it;
* the pair is taken only where its rays pass within the ray-gap limit.

A filled sighting is ``RECOVERED``. A gap is filled only between two accepted sightings, so no
label changes: where the marker's identity is wrong on both sides, the fill carries that (all 3
wrong fills of ``hard`` 83 and 97 lay there). So with ``sure`` (the pipeline's default) a gap is
filled only where both framing sightings are ones the two tracking runs agree on
(:func:`lipgen.recon.crosscheck.runs_agree`): each run labelled the dots afresh from its own end of
the clip, and reached the same dot. A frame in ``barred`` (a sighting the shared-dot check took
back) is never filled.

Measured (``renders/examples/tracking/g38.md``; score = accepted within 3 px - 10 x accepted over
3 px). Without ``sure`` the fill won on development (+119 on ``hard`` 83-102) but failed held-out
``hard`` 171-182: -43, accepted 83.7 -> 85.4 % but over 3 px 374 -> 403. With it: +39 on
development, and on its own fresh sets ``hard`` 183-190 +26 (accepted 88.80 -> 89.04 %) and ``default``
178-179 +28 (97.86 -> 98.14 %), with no sighting over 3 px added in any set.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from lipgen.recon.association import LOST, RECOVERED
from lipgen.recon.blobs import blob_peaks
from lipgen.recon.dots import DotSettings, detect_dots, ink_gray, refine_centroids
from lipgen.recon.tracks import Tracks
from lipgen.rig.pinhole import PinholeCamera, triangulate

__all__ = ["GAP_FILL_FRAMES", "short_gaps", "view_peaks", "fill_short_gaps", "gap_fill_line"]

GAP_FILL_FRAMES = 3
"""Longest gap filled, in frames."""


def short_gaps(accepted: np.ndarray, max_len: int) -> list[tuple[int, int, int]]:
    """Runs of frames where a marker is not accepted, with an accepted frame on each side.

    Parameters
    ----------
    accepted : (F, P) bool
    max_len : int
        Longest run returned, frames (at least 1).

    Returns
    -------
    list of (marker, start, stop)
        Frames ``start`` to ``stop - 1``; ``accepted[start - 1]`` and ``accepted[stop]`` are True.
    """
    accepted = np.asarray(accepted, dtype=bool)
    if accepted.ndim != 2:
        raise ValueError(f"accepted must be (frames, markers) bool, got shape {accepted.shape}")
    if isinstance(max_len, bool) or int(max_len) != max_len or max_len < 1:
        raise ValueError(f"max_len must be a whole number of frames >= 1, got {max_len!r}")
    out = []
    for i in range(accepted.shape[1]):
        edges = np.flatnonzero(np.diff(np.r_[1, accepted[:, i].astype(np.int8), 1]))
        for start, stop in zip(edges[::2], edges[1::2], strict=True):
            if start >= 1 and stop <= accepted.shape[0] - 1 and stop - start <= max_len:
                out.append((i, int(start), int(stop)))
    return out


def view_peaks(image, dots: DotSettings, floor: float) -> tuple[np.ndarray, np.ndarray]:
    """One view's peaks (k, 2): the detector's at ``floor``, then the curvature detector's; and its gray."""
    gray = ink_gray(image)
    uv, _ = detect_dots(image, replace(dots, min_contrast=floor))
    blobs, _ = blob_peaks(gray, dots, exclude=uv)
    return np.vstack([uv.reshape(-1, 2), blobs.reshape(-1, 2)]), gray


def fill_short_gaps(tracks: tuple[Tracks, Tracks], frame_at: Callable[[int], tuple], cameras: tuple[
        PinholeCamera, PinholeCamera], accepted: np.ndarray, dots: DotSettings, floor: float,
        max_gap: float, max_len: int = GAP_FILL_FRAMES, sure: np.ndarray | None = None,
        barred: np.ndarray | None = None) -> tuple[tuple[Tracks, Tracks], dict]:
    """Fill each marker's short gaps between accepted sightings (see the module docstring).

    Parameters
    ----------
    tracks : (virtual, real) Tracks
    frame_at : callable
        ``frame_at(f)`` -> the (virtual, real) images of frame ``f``.
    cameras : (virtual, real) PinholeCamera
    accepted : (F, P) bool
        Markers accepted in both views (rays within ``max_gap``).
    dots : DotSettings
        The tracker's detector (its ``sigma``, ``separation`` and ``window``).
    floor : float
        Least contrast of a detector peak (the tracker's least floor).
    max_gap : float
        The ray-gap limit, mm.
    max_len : int
        Longest gap filled, frames.
    sure : (F, P) bool, optional
        Sightings whose label is sure (:func:`lipgen.recon.crosscheck.runs_agree`): a gap is filled
        only between two of them.
    barred : (F, P) bool, optional
        Frame-marker pairs never filled.

    Returns
    -------
    (virtual, real) : Tracks
        Copies, with the filled sightings.
    record : dict
        ``gaps`` (frame-marker pairs in short gaps, barred ones left out), ``filled`` (of them,
        filled) and ``unsure`` (of them, not tried: a framing sighting is not in ``sure``).
    """
    F, P = tracks[0].uv.shape[:2]
    accepted = np.asarray(accepted, dtype=bool)
    if accepted.shape != (F, P):
        raise ValueError(f"accepted must have shape {(F, P)} (frames, markers), got {accepted.shape}")
    for name, mask in (("sure", sure), ("barred", barred)):
        if mask is not None and np.shape(mask) != (F, P):
            raise ValueError(f"{name} must have shape {(F, P)} (frames, markers), got {np.shape(mask)}")
    uv = [t.uv.copy() for t in tracks]
    status = [t.status.copy() for t in tracks]
    todo: dict[int, list[tuple[int, float, int, int]]] = {}
    unsure = 0
    for i, start, stop in short_gaps(accepted, max_len):
        if sure is not None and not (sure[start - 1, i] and sure[stop, i]):
            unsure += stop - start
            continue
        for f in range(start, stop):
            if barred is not None and barred[f, i]:
                continue
            todo.setdefault(f, []).append((i, (f - start + 1) / (stop - start + 1), start - 1, stop))
    reach, held_r = dots.separation, dots.separation / 2
    filled = 0
    for f in sorted(todo):
        images = frame_at(f)
        found = [view_peaks(images[v], dots, floor) for v in range(2)]
        for i, alpha, before, after in todo[f]:
            pair = []
            for v in range(2):
                guess = (1 - alpha) * uv[v][before, i] + alpha * uv[v][after, i]
                own = uv[v][f, i]
                if status[v][f, i] != LOST and np.linalg.norm(own - guess) <= reach:
                    pair.append(own)
                    continue
                peaks, gray = found[v]
                others = np.delete(uv[v][f], i, axis=0)
                others = others[np.all(np.isfinite(others), axis=1)]
                free = np.ones(len(peaks), dtype=bool)
                if len(others) and len(peaks):
                    free = np.linalg.norm(peaks[:, None] - others[None], axis=2).min(1) >= held_r
                d = np.linalg.norm(peaks - guess, axis=1) if len(peaks) else np.zeros(0)
                near = np.flatnonzero(free & (d <= reach))
                if len(near) == 0:
                    break
                got = refine_centroids(gray, peaks[near[np.argmin(d[near])]][None], dots.sigma,
                                       window=dots.window)[0]
                if not np.linalg.norm(got - guess) <= reach:
                    break
                pair.append(got)
            if len(pair) < 2:
                continue
            gap = triangulate(cameras[1], pair[1][None], cameras[0], pair[0][None])[1][0]
            if not gap <= max_gap:
                continue
            for v in range(2):
                if not np.array_equal(pair[v], uv[v][f, i]):
                    uv[v][f, i], status[v][f, i] = pair[v], RECOVERED
            filled += 1
    out = tuple(replace(t, uv=uv[v], status=status[v], visible=status[v] != LOST)
                for v, t in enumerate(tracks))
    return out, {"gaps": int(sum(len(w) for w in todo.values())) + unsure, "filled": filled, "unsure": unsure}


def gap_fill_line(record: dict | None) -> str | None:
    """One sentence on what :func:`fill_short_gaps` did, for the command's output and the report; None when
    it did not run (``record`` None: ``gap_fill`` off, or a reconstruction made before it)."""
    if not record:
        return None
    unsure = record.get("unsure", 0)
    tail = (f"; {unsure} more lay between sightings the two tracking runs did not agree on, and were left"
            if unsure else "")
    return (f"Filled {record['filled']} of {record['gaps']} marker sighting(s) lost in short gaps between "
            f"accepted sightings, where both views show a dot near the interpolated position{tail}.")
