"""Which of two tracking runs carries a disputed marker on from the frames where both agree.

Where the forward and the reversed run put a marker on different dots over a span of frames, one of them
took a wrong dot at the span's edge: a slip to a neighbour's dot, or a wrong pick when the marker was
found again. Just outside the span both runs saw the marker on one dot. The run whose sighting inside the
span continues that motion (the agreed position, moved on by the agreed velocity) stayed on the dot; the
other jumped. This judges the span in the image, without the layout, which predicts the mouth corners
worst (``renders/examples/tracking/s45.md``).

Off in the pipeline (``ReconstructSettings.cross_check_continuity``): it gained on development sets but
changed nothing on its held-out ones (``renders/examples/tracking/s47.md``).

Only agreed sightings are references. A frame where one run alone sees the marker would make that run's
own track the reference, and a run that was already wrong there would be judged continuous (``hard`` 181
and 196 on the development sets).
"""

from __future__ import annotations

import numpy as np

from lipgen.recon.tracks import Tracks, seen, true_runs

__all__ = ["span_jumps", "continuity_verdict"]


def _shared(first: tuple[Tracks, Tracks], second: tuple[Tracks, Tracks]) -> np.ndarray:
    """(2, F, P) bool: where both runs see each marker, per view."""
    return np.stack([seen(a) & seen(b) for a, b in zip(first, second, strict=True)])


def span_jumps(first: tuple[Tracks, Tracks], second: tuple[Tracks, Tracks], disputed: np.ndarray,
               m: int, start: int, stop: int, shared=None) -> tuple[float, float, int]:
    """How far each run's sightings at a disputed span's ends lie from the agreed motion just outside.

    At each end of frames ``start .. stop - 1`` of marker ``m``, in each view where both runs see the
    marker at the span's edge frame and the frame just outside it: the reference is the runs' common
    sighting outside, moved on by its velocity where the next frame out is agreed too.

    Parameters
    ----------
    first, second : (virtual, real) Tracks
        The same clip, each (F, P).
    disputed : (F, P) bool
    m, start, stop : int
    shared : (2, F, P) bool, optional
        Where both runs see each marker, per view (:func:`lipgen.recon.tracks.seen` of each); computed when
        not given.

    Returns
    -------
    jump_first, jump_second : float
        Pixels, summed over the terms.
    n : int
        The number of (end, view) terms; 0 where no end has an agreed neighbour.
    """
    F = disputed.shape[0]
    if shared is None:
        shared = _shared(first, second)
    ja = jb = 0.0
    n = 0
    for outside, inside, step in ((start - 1, start, -1), (stop, stop - 1, 1)):
        if not 0 <= outside < F:
            continue
        for a, b, both in zip(first, second, shared[:, :, m], strict=True):
            if not (both[inside] and both[outside]):
                continue
            ref = a.uv[outside, m]       # undisputed and seen by both: the runs agree here
            beyond = outside + step
            if 0 <= beyond < F and both[beyond] and not disputed[beyond, m]:
                ref = 2 * ref - a.uv[beyond, m]
            ja += float(np.linalg.norm(a.uv[inside, m] - ref))
            jb += float(np.linalg.norm(b.uv[inside, m] - ref))
            n += 1
    return ja, jb, n


def continuity_verdict(first: tuple[Tracks, Tracks], second: tuple[Tracks, Tracks], disputed: np.ndarray,
                       ratio: float = 0.6) -> np.ndarray:
    """Per disputed span, the run that carries the agreed motion on (:func:`span_jumps`).

    Parameters
    ----------
    first, second : (virtual, real) Tracks
    disputed : (F, P) bool
    ratio : float
        A run wins where its jump is below ``ratio`` times the other's (the layout judge's ratio).

    Returns
    -------
    (F, P) int8
        As :func:`lipgen.recon.crosscheck.arbitrate`: 1 for the first run, 2 for the second, 0 where
        neither jumps clearly less or no end has an agreed neighbour.
    """
    disputed = np.asarray(disputed, bool)
    if disputed.ndim != 2 or disputed.shape != first[0].uv.shape[:2]:
        raise ValueError(f"disputed must be (F, P) = {first[0].uv.shape[:2]}, got {disputed.shape}")
    if not 0 < ratio <= 1:
        raise ValueError(f"ratio must be in (0, 1], got {ratio!r}")
    out = np.zeros(disputed.shape, np.int8)
    shared = _shared(first, second)
    for m in range(disputed.shape[1]):
        for start, stop in true_runs(disputed[:, m]):
            ja, jb, n = span_jumps(first, second, disputed, m, start, stop, shared)
            if n:
                out[start:stop, m] = 2 if jb < ratio * ja else 1 if ja < ratio * jb else 0
    return out
