"""Acquiring markers not seen yet on a later frame, from the layout registered to the markers seen.

The first frame's match (:func:`lipgen.recon.pointreg.match_to_expected`) leaves markers
unmatched where their dots are missing, ambiguous or beside lures; a short clip never shows them
again if nothing looks for them. Every later frame, :class:`lipgen.recon.track.MarkerTracker`
places the layout on the markers it tracks (:func:`place_layout`: a similarity and the local
offsets of the seen markers) and takes dots for the missing ones by the first frame's rules
(:func:`acquire`: one-to-one within a gate, unambiguous). A group missing together (one side of
the lower lip, the mouth open) is placed by a shrinking-gate registration of its own
(:func:`acquire_layout`).
"""

from __future__ import annotations

import numpy as np

from lipgen._validate import as_float_array
from lipgen.recon.pointreg import _ambiguous, assign, layout_spacing, similarity_2d

__all__ = ["place_layout", "acquire", "acquire_layout"]


def place_layout(expected: np.ndarray, uv: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """Where the markers not seen are, from the layout registered to the markers seen.

    The similarity from the seen markers' layout positions to their positions ``uv``, then each
    marker moved by the Gaussian-weighted mean of the seen markers' residual offsets (weights by
    distance in the layout, width one typical marker spacing): :func:`register_nonrigid`'s last
    step, with the matches known.

    Parameters
    ----------
    expected : (P, 2) float
        The layout.
    uv : (P, 2) float
        Positions of the markers, pixels; used where ``seen``.
    seen : (P,) bool
        At least 3.

    Returns
    -------
    (P, 2) float
        The registered layout; equal to ``uv`` where ``seen``.
    """
    expected = as_float_array(expected, "expected", (None, 2))
    uv = as_float_array(uv, "uv", (len(expected), 2), finite=False)
    seen = np.asarray(seen, dtype=bool)
    if seen.shape != (len(expected),) or seen.sum() < 3 or not np.all(np.isfinite(uv[seen])):
        raise ValueError(f"seen must be a ({len(expected)},) bool mask of at least 3 finite uv rows, "
                         f"got shape {seen.shape} with {int(seen.sum())} set")
    s, R, t = similarity_2d(expected[seen], uv[seen])
    base = s * expected @ R.T + t
    width = layout_spacing(expected)
    w = np.exp(-0.5 * (np.linalg.norm(expected[:, None] - expected[seen][None], axis=2) / width) ** 2)
    out = base + (w @ (uv[seen] - base[seen])) / np.maximum(w.sum(1, keepdims=True), 1e-300)
    out[seen] = uv[seen]
    return out


def acquire(aligned: np.ndarray, dots: np.ndarray, wanted: np.ndarray, free: np.ndarray, gate: float,
            ratio: float = 0.6) -> np.ndarray:
    """Match the ``wanted`` markers to free dots near the registered layout, unambiguously.

    The first-frame rules of :func:`match_to_expected` on a later frame: one-to-one assignment of
    the wanted markers' positions ``aligned`` to the ``free`` dots within ``gate``, and a match is
    kept only when the dot is closer to its marker than ``ratio`` times its distance to any other
    marker's position, and than ``ratio`` times the distance from the marker to any other dot
    (taken or free).

    Parameters
    ----------
    aligned : (P, 2) float
        Every marker's position: seen markers where they are, the others from
        :func:`place_layout`.
    dots : (k, 2) float
        This frame's dots.
    wanted : (P,) bool
        Markers to acquire.
    free : (k,) bool
        Dots no marker has taken.
    gate : float
        Largest distance (pixels) from a marker's position to its dot.
    ratio : float
        Ambiguity ratio.

    Returns
    -------
    (P,) int
        Index into ``dots`` for the wanted markers acquired, -1 elsewhere.
    """
    aligned = as_float_array(aligned, "aligned", (None, 2), finite=False)
    dots = as_float_array(dots, "dots", (None, 2))
    wanted, free = np.asarray(wanted, dtype=bool), np.asarray(free, dtype=bool)
    if wanted.shape != (len(aligned),) or free.shape != (len(dots),):
        raise ValueError(f"wanted must have shape ({len(aligned)},) and free ({len(dots)},), "
                         f"got {wanted.shape} and {free.shape}")
    gates = np.where(wanted & np.all(np.isfinite(aligned), axis=1), float(gate), 0.0)
    match = np.full(len(aligned), -1, dtype=np.int64)
    if not free.any() or not (gates > 0).any():
        return match
    idx = np.flatnonzero(free)
    sub = assign(np.where((gates > 0)[:, None], aligned, np.nan), dots[idx], gates)
    match[sub >= 0] = idx[sub[sub >= 0]]
    match[_ambiguous(aligned, dots, match, ratio)] = -1
    return match


def acquire_layout(expected: np.ndarray, uv: np.ndarray, seen: np.ndarray, wanted: np.ndarray,
                   dots: np.ndarray, free: np.ndarray, gate: float, ratio: float = 0.6,
                   iterations: int = 5) -> np.ndarray:
    """Acquire the ``wanted`` markers on free dots where the layout, registered to the seen ones, puts them.

    A group of markers missing together (the lower lip's side, with the mouth open) is placed
    badly by its seen neighbours alone, which are mostly on the other lip. So, as in
    :func:`register_nonrigid`: alternately place the layout (:func:`place_layout`) from the seen
    markers and the wanted markers' tentative dots, and assign the wanted markers one-to-one to
    free dots within a gate shrinking from ``3 * gate`` to ``gate``. The final matches are then
    made by :func:`acquire` with each wanted marker placed from all the others (itself left out),
    so its own tentative dot cannot vouch for itself.

    Parameters
    ----------
    expected : (P, 2) float
        The layout.
    uv : (P, 2) float
        Positions of the seen markers, pixels.
    seen : (P,) bool
        At least 3.
    wanted, dots, free, gate, ratio
        As in :func:`acquire`.
    iterations : int
        Placement steps.

    Returns
    -------
    (P,) int
        Index into ``dots`` for the wanted markers acquired, -1 elsewhere.
    """
    wanted, free = np.asarray(wanted, dtype=bool), np.asarray(free, dtype=bool)
    seen = np.asarray(seen, dtype=bool)
    idx = np.flatnonzero(free)
    tent = np.full(len(expected), -1, dtype=np.int64)

    def placed() -> np.ndarray:
        """Each wanted marker placed from the seen markers and the other wanted markers' tentative dots."""
        at = np.where((tent >= 0)[:, None], dots[np.maximum(tent, 0)], uv)
        out = place_layout(expected, at, seen)
        for i in np.flatnonzero(wanted):
            others = seen | (tent >= 0)
            others[i] = False
            if (tent >= 0).any():
                out[i] = place_layout(expected, at, others)[i]
        return out

    pos = placed()
    if len(idx):
        for k in range(max(iterations, 1)):
            g = gate * (3.0 - 2.0 * k / max(iterations - 1, 1))
            sub = assign(np.where(wanted[:, None], pos, np.nan), dots[idx], np.where(wanted, g, 0.0))
            tent = np.where(sub >= 0, idx[np.maximum(sub, 0)], -1)
            pos = placed()
    return acquire(pos, dots, wanted, free, gate, ratio)
