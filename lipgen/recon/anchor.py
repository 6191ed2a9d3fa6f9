"""Where tracking starts: the first frame whose markers are all matched in both views.

The tracker labels the dots once, in its first frame (:mod:`lipgen.recon.firstframe`), and carries the
labels on from there. A clip that opens with the mouth wide, blurred or half hidden leaves markers
unmatched or wrongly matched there, and the tracker carries that for many frames (``default`` 2 of the
development sets opens 26 mm wide, against 14 mm at rest). :func:`track_from_anchor` runs the
first-frame stage alone on frames 0, ``step``, 2 ``step``, ... and takes the first one at which every
marker (the nose included) is matched in both views; frame 0 itself when it is one, or when none is.
It tracks forward from that frame to the end and backward from it to frame 0, and joins the two runs.

A frame with every marker matched is not always rightly matched: on the 12 development sets 5 of the 24
such frames among those probed had 1 or 2 markers on a wrong dot, and frame 0 (the clips open near rest)
had one in 2 of 12. So frame 0 is kept whenever it is complete. The frame that matches the most
markers, whatever their number, was tried twice and lost on ``hard``, where the busiest frame often
holds a lure (``renders/examples/tracking/hard15j_anchor.md``, and A5 in ``anchor23.md``); no ``hard``
frame probed so far was complete, so there this rule leaves the tracks as they were.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import fields

import numpy as np

from lipgen.recon.tracks import Tracks

__all__ = ["ANCHOR_STEP", "anchor_line", "find_anchor", "join_runs", "track_from_anchor"]

ANCHOR_STEP = 5
"""Frames between the candidate first frames (every 5th: a 150-frame clip probes at most 30)."""

TrackFn = Callable[[Iterable[np.ndarray], Callable[[int], None] | None], tuple[Tracks, Tracks]]


def _check_step(step) -> int:
    if isinstance(step, bool) or not isinstance(step, (int, np.integer)) or step < 1:
        raise ValueError(f"anchor step must be a positive whole number of frames, got {step!r}")
    return int(step)


def find_anchor(frame_at: Callable[[int], np.ndarray], n_frames: int, track: TrackFn,
                step: int = ANCHOR_STEP) -> tuple[int, dict]:
    """The first of frames 0, ``step``, ... whose first-frame stage matches every marker in both views.

    Parameters
    ----------
    frame_at : callable
        ``frame_at(i)`` -> frame ``i``'s raw image.
    n_frames : int
    track : callable
        ``track(frames, progress)`` -> (virtual, real) :class:`Tracks`: the tracker on those frames.
    step : int

    Returns
    -------
    frame : int
        0 when frame 0 is complete or no probed frame is.
    record : dict
        ``frame``, ``step``, ``probed`` (frames tried, in order) and ``matched`` (markers matched in both
        views at each).
    """
    step = _check_step(step)
    if n_frames < 1:
        raise ValueError(f"find_anchor needs at least one frame, got n_frames={n_frames}")
    probed, matched, frame = [], [], 0
    for k in range(0, n_frames, step):
        virtual, real = track([frame_at(k)], None)
        both = virtual.visible[0] & real.visible[0]
        probed.append(k)
        matched.append(int(both.sum()))
        if both.all():
            frame = k
            break
    return frame, {"frame": frame, "step": step, "probed": probed, "matched": matched,
                   "markers": int(virtual.n_markers)}


def join_runs(backward: Tracks, forward: Tracks) -> Tracks:
    """One view's tracks from a run backward from the anchor to frame 0 and one forward from it.

    Parameters
    ----------
    backward : Tracks
        Frames anchor, anchor - 1, ..., 0 (anchor + 1 frames).
    forward : Tracks
        Frames anchor, ..., F - 1.

    Returns
    -------
    Tracks
        Frames 0 ... F - 1: the backward run's frames before the anchor, in time order, then the forward
        run (the anchor frame is the forward run's; both runs start there from the same first-frame stage).
    """
    if backward.n_markers != forward.n_markers:
        raise ValueError(f"the runs track {backward.n_markers} and {forward.n_markers} markers")
    before = slice(backward.n_frames - 1, 0, -1)   # anchor - 1, ..., 0 reversed into time order

    def joined(name):
        a, b = getattr(backward, name), getattr(forward, name)
        return None if a is None or b is None else np.concatenate([a[before], b])   # rejected may be None

    return Tracks(**{f.name: joined(f.name) for f in fields(Tracks)})


def track_from_anchor(frame_at: Callable[[int], np.ndarray], n_frames: int, track: TrackFn,
                      step: int | None = ANCHOR_STEP,
                      progress: Callable[[int], None] | None = None) -> tuple[tuple[Tracks, Tracks], dict]:
    """Track every frame, starting at :func:`find_anchor`'s frame (see the module docstring).

    Parameters
    ----------
    frame_at : callable
        ``frame_at(i)`` -> frame ``i``'s raw image (read again for each run: nothing is held in memory).
    n_frames : int
    track : callable
        As :func:`find_anchor`.
    step : int or None
        None: from frame 0, no probe (the tracker as it was before anchors).
    progress : callable, optional
        Called once per frame of the clip as it is tracked (the anchor frame once).

    Returns
    -------
    (virtual, real) : Tracks
    record : dict
        :func:`find_anchor`'s (``frame`` 0, ``probed`` empty when ``step`` is None).
    """
    if step is None:
        frame, record = 0, {"frame": 0, "step": None, "probed": [], "matched": []}
    else:
        frame, record = find_anchor(frame_at, n_frames, track, step)

    def forward_progress(t):
        progress(frame + t)

    def backward_progress(t):
        if t > 0:                   # the backward run starts on the anchor frame, counted by the forward run
            progress(frame - t)

    report = progress is not None
    forward = track((frame_at(i) for i in range(frame, n_frames)), forward_progress if report else None)
    if frame == 0:
        return forward, record
    backward = track((frame_at(i) for i in range(frame, -1, -1)), backward_progress if report else None)
    return (join_runs(backward[0], forward[0]), join_runs(backward[1], forward[1])), record


def anchor_line(record: dict | None) -> str | None:
    """One sentence saying where tracking started, for the command's output and the report; None when it
    started at frame 0 (or ``record`` is None: reconstructions made before anchors started there)."""
    if not record or not record.get("frame"):
        return None
    return (f"Tracking started at frame {record['frame']}, the first probed frame with every mark matched in "
            f"both views (frame 0: {record['matched'][0]} of {record['markers']}); the frames before it were "
            "tracked backward from there.")
