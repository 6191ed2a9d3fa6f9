"""A marker's track that jumps: its runs that disagree are told apart, and all but the longest taken back.

The tracker can hold a marker on a lure for some frames (the crease at a mouth corner, seen in both views,
so its rays meet) and then re-acquire it on its own dot: on development ``hard`` 172, 196 and 198 (truth
read for the diagnosis only) ``upper_corner_right``, ``corner_left`` and ``upper_corner_left`` sat 8-14 px
off in both views for 6-8 accepted frames, then jumped onto their dots and held them to the clip's end.
Between two frames the marker is accepted in, its move is compared with its neighbours' move
(:func:`lipgen.recon.backfill.neighbour_motion`): where it differs by more than ``jump`` pixels (plus
``spread`` times the spread of the neighbours' own moves) in both views, the two frames hold different
things. The accepted frames are grouped into tracks that agree with each other (a run joins the group
whose latest frame it continues); the group with the most frames stands when it has more than ``ratio``
times the frames of the next, and the others are taken back in both views; otherwise every group is taken
back. The walk-on (:mod:`lipgen.recon.extend`) then walks a kept track into the frames taken back.

The longer track is not always the right one: on ``hard`` 199 the tracker held ``upper_corner_left`` on
a lure for 17 accepted frames and on its dot for 14, alternating, and keeping the longer lost 102 on the
score (``renders/examples/tracking/s40.md``). A lost sighting costs a tenth of a wrong one, hence the ratio.
Where the lips deform fast (``default`` 182-185) right markers move 5+ px against their neighbours' mean;
the neighbours then disagree with each other too, hence ``spread``. The pipeline's defaults (5 px, ratio 1.5,
spread 2) are :attr:`lipgen.recon.settings.ReconstructSettings.split_runs`'s (``s41.md``).
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen.recon.backfill import neighbour_moves
from lipgen.recon.outofplace import take_back
from lipgen.recon.pointreg import layout_spacing
from lipgen.recon.tracks import Tracks

__all__ = ["disagreeing_runs", "take_back_disagreeing", "split_runs_line"]

log = logging.getLogger(__name__)


def _jump(tracks, reference, spacing, accepted, m: int, a: int, b: int, spread: float = 0.0) -> float:
    """The smaller over the views of marker ``m``'s move from frame ``a`` to ``b`` less its neighbours', less
    ``spread`` times the spread of the neighbours' own moves (NaN where a view has no neighbour seen in both
    frames)."""
    ok = accepted[a] & accepted[b]
    out = []
    for v in range(2):
        uv = tracks[v].uv
        got = neighbour_moves(reference[v], uv[a], uv[b], ok, m, spacing[v])
        if got is None:
            return np.nan
        out.append(float(np.linalg.norm(uv[b, m] - uv[a, m] - got[0])) - spread * got[1])
    return min(out)


def disagreeing_runs(tracks: tuple[Tracks, Tracks], accepted, reference, jump: float,
                     markers=None, ratio: float = 1.0, spread: float = 0.0) -> tuple[np.ndarray, list[dict]]:
    """The accepted sightings to take back where a marker's track jumps (see the module docstring).

    Parameters
    ----------
    tracks : (virtual, real) Tracks
        F frames, P markers each.
    accepted : (F, P) bool
        The sightings both views agree on.
    reference : (2, P, 2) float
        The layout in each view (the neighbours' weights fall off with distance in it).
    jump : float
        Pixels by which a marker's move may differ from its neighbours' in the better view.
    markers : (P,) bool, optional
        The markers judged (default: all); the others still count as neighbours.
    ratio : float
        The longest track stands only when it has more than ``ratio`` times the frames of the next;
        otherwise every track of the marker is taken back. At least 1.
    spread : float
        The limit is ``jump`` plus ``spread`` times the spread of the neighbours' own moves between the two
        frames (:func:`lipgen.recon.backfill.neighbour_moves`). At least 0.

    Returns
    -------
    taken : (F, P) bool
    groups : list of dict
        One per marker judged that was split: ``marker``, ``kept`` (frames) and ``taken`` (frames).
    """
    accepted = np.asarray(accepted, dtype=bool)
    F, P = accepted.shape
    if tracks[0].uv.shape[:2] != (F, P) or tracks[1].uv.shape[:2] != (F, P):
        raise ValueError(f"accepted has shape {accepted.shape}; the tracks have "
                         f"{tracks[0].uv.shape[:2]} and {tracks[1].uv.shape[:2]} frames x markers")
    reference = np.asarray(reference, dtype=float)
    if reference.shape != (2, P, 2):
        raise ValueError(f"reference must be (2, {P}, 2), got shape {reference.shape}")
    if not (np.isfinite(jump) and jump > 0):
        raise ValueError(f"jump must be a positive number of pixels, got {jump!r}")
    if not (np.isfinite(ratio) and ratio >= 1):
        raise ValueError(f"ratio must be a number >= 1, got {ratio!r}")
    if not (np.isfinite(spread) and spread >= 0):
        raise ValueError(f"spread must be a number >= 0, got {spread!r}")
    judged = np.ones(P, dtype=bool) if markers is None else np.asarray(markers, dtype=bool)
    spacing = [layout_spacing(reference[v][np.all(np.isfinite(reference[v]), axis=1)]) for v in range(2)]
    taken = np.zeros((F, P), dtype=bool)
    groups = []
    for m in np.flatnonzero(judged):
        frames = np.flatnonzero(accepted[:, m])
        chains: list[list[int]] = []
        for f in frames:
            # A frame joins the chain whose latest frame it continues best (within ``jump``).
            best, best_j = None, jump
            for c in chains:
                j = _jump(tracks, reference, spacing, accepted, m, c[-1], f, spread)
                if j <= best_j:
                    best, best_j = c, j
            if best is None:
                chains.append([f])
            else:
                best.append(f)
        if len(chains) < 2:
            continue
        chains.sort(key=len, reverse=True)
        keep = chains[0] if len(chains[0]) > ratio * len(chains[1]) else None
        out = [f for c in chains if c is not keep for f in c]
        taken[out, m] = True
        groups.append({"marker": int(m), "kept": [] if keep is None else [int(f) for f in keep],
                       "taken": sorted(int(f) for f in out)})
    return taken, groups


def take_back_disagreeing(tracks: tuple[Tracks, Tracks], accepted, reference, jump: float, markers=None,
                          names=None, ratio: float = 1.0, spread: float = 0.0
                          ) -> tuple[tuple[Tracks, Tracks], list[dict]]:
    """The tracks with :func:`disagreeing_runs`' sightings taken back in both views (NaN, ``LOST``, marked
    ``rejected``), and its groups; ``names`` (marker names) are for the log."""
    taken, groups = disagreeing_runs(tracks, accepted, reference, jump, markers, ratio, spread)
    for g in groups:
        m = g["marker"]
        log.info("%s jumps between its accepted frames: %d frame(s) kept, %d taken back (%s)",
                 m if names is None else names[m], len(g["kept"]), len(g["taken"]),
                 ", ".join(map(str, g["taken"])))
    return take_back(tracks, taken), groups


def split_runs_line(groups: list[dict] | None) -> str | None:
    """One sentence for the report: how many sightings were taken back where a track jumps (None: not run)."""
    if groups is None:
        return None
    if not groups:
        return "Split tracks: no marker's track jumped between accepted frames."
    n = sum(len(g["taken"]) for g in groups)
    ties = sum(not g["kept"] for g in groups)   # no track long enough to stand: all taken back
    tail = f" ({ties} of them with no track long enough to keep)" if ties else ""
    return (f"Split tracks: {len(groups)} marker(s) jumped between accepted frames{tail}; {n} sighting(s) "
            f"off the kept tracks taken back.")
