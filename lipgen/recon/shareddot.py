"""Two markers on one dot in both views: both sightings are taken back.

A dot is one marker's. When the tracks hold two markers on the same dot in both views, their rays
meet and every check that judges one marker at a time passes: each pair's point is a real dot's,
on the lip, near the layout. On the 20 spent ``hard`` development sets (83-122, truth read for the
diagnosis only) 70 pair-frames held two markers within 0.7 px of each other in both views, and in
every one of them one marker was wrong (``lower_corner_right`` on ``corner_right``'s dot for 34
frames of ``hard`` 119, from the first frame; ``corner_right`` on ``lower_corner_right``'s for 20 of
``hard`` 111). No two markers' true projections came within 2.5 px of each other in both views; the
nearest two distinct sightings seen in both views were 3.7 px apart.

Which of the two is wrong is not decided here, because nothing at hand decides it reliably
(``renders/examples/tracking/dup37.md``): the 3-D layout, which judges the cross-check's disputes,
chose the intruder in all 10 spans it decided on fresh ``hard`` 123-138 and ``default`` 166-168 (a
marker reaches a neighbour's dot where its layout prediction points, so the layout favours it), and
the tracks' continuity (who held the dot before and after) chose wrongly on the longest span. Both
sightings are taken back: a wrong sighting costs far more than a lost one. Held out (fresh ``hard``
139-154, run once): accepted sightings over 3 px 323 -> 193, the score (within 3 px - 10 x over)
15811 -> 16981; ``default`` 169-171 had no shared dot.

:func:`shared_dots` finds them: both markers seen in both views, their sightings within ``tol`` pixels
of each other in each view.
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen.recon.outofplace import take_back
from lipgen.recon.tracks import Tracks, seen, true_runs

__all__ = ["shared_dots", "take_back_shared", "shared_dot_line"]

log = logging.getLogger(__name__)


def shared_dots(tracks: tuple[Tracks, Tracks], tol: float) -> tuple[np.ndarray, list[dict]]:
    """The sightings to take back where two markers hold one dot in both views (see the module docstring).

    Parameters
    ----------
    tracks : (virtual, real) Tracks
        F frames, P markers each.
    tol : float
        Two sightings nearer than this in a view (pixels) are on one dot; at most half the
        detector's one-dot distance, so that two dots fitted apart are never taken for one.

    Returns
    -------
    taken : (F, P) bool
        Sightings to take back (both views).
    spans : list of dict
        One per span of consecutive frames in which a pair of markers shares a dot: ``markers``
        (i, j), i < j, and ``frames`` (start, stop).
    """
    tv, tr = tracks
    if tr.uv.shape != tv.uv.shape or tv.uv.ndim != 3 or tv.uv.shape[-1] != 2:
        raise ValueError(f"tracks must both have shape (F, P, 2), got {tv.uv.shape} and {tr.uv.shape}")
    number = isinstance(tol, int | float | np.floating) and not isinstance(tol, bool)
    if not (number and np.isfinite(tol) and tol > 0):
        raise ValueError(f"tol must be a number > 0 (pixels), got {tol!r}")
    F, P = tv.uv.shape[:2]
    both = seen(tv) & seen(tr)
    near = np.ones((F, P, P), dtype=bool)
    for t in (tv, tr):
        uv = np.where(both[..., None], t.uv, np.nan)
        near &= np.linalg.norm(uv[:, :, None] - uv[:, None], axis=-1) < tol   # NaN compares False
    near &= ~np.eye(P, dtype=bool)
    taken = near.any(axis=2)
    spans = [{"markers": (int(i), int(j)), "frames": span}
             for i, j in zip(*np.nonzero(np.triu(near.any(axis=0), 1)), strict=True)
             for span in true_runs(near[:, i, j])]
    return taken, spans


def take_back_shared(tracks: tuple[Tracks, Tracks], tol: float, names=None
                     ) -> tuple[tuple[Tracks, Tracks], list[dict]]:
    """The tracks with :func:`shared_dots`' sightings taken back in both views (NaN, ``LOST``, marked
    ``rejected``), and its spans; ``names`` (marker names) are for the log."""
    taken, spans = shared_dots(tracks, tol)
    for s in spans:
        (i, j), (start, stop) = s["markers"], s["frames"]
        log.info("%s and %s on one dot in both views, frames %d-%d: both taken back",
                 i if names is None else names[i], j if names is None else names[j], start, stop - 1)
    return take_back(tracks, taken), spans


def shared_dot_line(spans: list[dict] | None, names) -> str | None:
    """One sentence on what :func:`take_back_shared` did, for ``lipgen reconstruct``'s output and the
    report; None where no two markers shared a dot (or the reconstruction predates the check).
    ``names``: the markers' names, indexed as in ``spans``."""
    if not spans:
        return None
    parts = []
    for s in spans[:4]:
        (i, j), (start, stop) = s["markers"], s["frames"]
        frames = f"frame {start}" if stop - start == 1 else f"frames {start}-{stop - 1}"
        parts.append(f"{names[i]} and {names[j]} in {frames}")
    more = f"; and {len(spans) - 4} more span(s)" if len(spans) > 4 else ""
    return ("Two markers held one dot in both views, so both were taken back there (one of them is on "
            "the other's dot): " + "; ".join(parts) + more + ".")
