"""Frame-to-frame data association for :mod:`lipgen.recon.track`: which dot is which marker.

Prediction of every marker (motion, global jumps, groups jumping on their own, local offsets for
markers not seen yet), the one-to-one assignment that prefers the correlation peak but accepts
motion-predicted matches only when unambiguous, and the guards that keep look-alike neighbours
from swapping: merged dots, reversed pairs, and lost markers carried along with their neighbours.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from lipgen.recon.pointreg import assign, register_points, similarity_2d

__all__ = ["TRACKED", "RECOVERED", "CORRELATION_ONLY", "LOST", "assign_two_routes", "predict", "shift_group",
           "drop_merged", "fix_order", "carry_lost_markers"]

TRACKED, RECOVERED, CORRELATION_ONLY, LOST = 0, 1, 2, 3
"""Per-frame status of a marker: correlation agreed with a detected dot; correlation failed and
the dot was found from the motion prediction; no dot detected but a confident correlation peak;
not found (not visible)."""

_BIG = 1e12


def assign_two_routes(cand: np.ndarray, pred: np.ndarray, dots: np.ndarray, gates: np.ndarray,
                       pred_gates: np.ndarray, corr_ok: np.ndarray, allowed: np.ndarray | None = None,
                       ratio: float = 0.6, round_dots: np.ndarray | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """One-to-one assignment of markers to dots, preferring the correlation peak.

    A dot within ``gates`` of a marker's correlation peak costs its distance. Without a
    correlation peak (failed, or locked onto a dot another marker owns), a marker may take a
    dot by its motion prediction only when the match is unambiguous: the dot is within
    ``pred_gates``, it is the prediction's nearest dot by a margin (``ratio`` of the second
    nearest), and no other marker's position is nearly as close to it. A wrong dot taken here
    would otherwise start a chain of swaps. Such matches cost more than any peak match.
    ``round_dots (k,) bool`` marks the dots that look like whole dots; the others (elongated
    blobs, such as a dot foreshortened at the lip corner, or a crease) can be taken only by the
    correlation route, but they still count as rivals in the prediction route's nearest-dot test:
    a marker whose own dot is foreshortened must not take the nearest round blob instead.
    Returns (match (P,) int, -1 for none; via_correlation (P,) bool).
    """
    out = np.full(len(cand), -1, dtype=np.int64)
    via = np.zeros(len(cand), dtype=bool)
    ok = np.all(np.isfinite(pred), axis=1)
    if len(dots) == 0 or not ok.any():
        return out, via
    d_cand = np.linalg.norm(cand[:, None] - dots[None], axis=2)
    d_pred = np.linalg.norm(pred[:, None] - dots[None], axis=2)
    d_cand[~ok] = d_pred[~ok] = np.inf
    peak_route = corr_ok[:, None] & (d_cand <= gates[:, None])
    pred_route = d_pred <= pred_gates[:, None]
    if allowed is not None:
        peak_route &= allowed
        pred_route &= allowed
    if round_dots is not None:
        pred_route &= np.asarray(round_dots, dtype=bool)[None, :]
    if len(dots) > 1:
        two = np.partition(d_pred, 1, axis=1)[:, :2]
        pred_route &= (d_pred == two[:, :1]) & (two[:, :1] < ratio * two[:, 1:])
    if len(cand) > 1:
        where = np.where(corr_ok[:, None], d_cand, d_pred)              # each marker's best guess
        two = np.partition(where, 1, axis=0)[:2]
        pred_route &= (d_pred < ratio * two[1:]) | ((where == two[:1]) & (two[:1] < ratio * two[1:]))
    cost = np.where(peak_route, d_cand, np.where(pred_route, d_pred + gates.max() + 1.0, _BIG))
    rows, cols = linear_sum_assignment(cost)
    good = cost[rows, cols] < _BIG
    out[rows[good]] = cols[good]
    via[rows[good]] = peak_route[rows[good], cols[good]]
    return out, via


def predict(last: np.ndarray, vel: np.ndarray, gap: np.ndarray, reference: np.ndarray | None,
             dots: np.ndarray, gate: float) -> np.ndarray:
    """Where each marker should be in this frame, NaN if unknown.

    Constant velocity from the last sighting, corrected by the similarity that best aligns the
    predicted layout with this frame's dots (this catches sudden global jumps, which would
    otherwise take the correlation to a neighbouring dot). Markers never seen are placed by the
    local offsets from the seen ones (see the code).
    """
    pred = last + vel * (gap == 0)[:, None]   # a lost marker was carried with its neighbours
    known = np.all(np.isfinite(pred), axis=1)
    if known.sum() >= 3 and len(dots) >= 3:
        match, aligned = register_points(dots, pred[known], gate)
        n = int((match >= 0).sum())
        if n >= max(3, known.sum() // 2) and _plausible_jump(pred[known], aligned, dots, gate, n):
            pred[known] = aligned
    if reference is not None and (~known).any() and known.sum() >= 2:
        # Local: from the nearest seen markers, each offset by its reference offset (turned and
        # scaled by the global similarity), so deformation elsewhere does not move the guess.
        s, R, _ = similarity_2d(reference[known], pred[known])
        k_idx = np.flatnonzero(known)
        for i in np.flatnonzero(~known):
            d = np.linalg.norm(reference[k_idx] - reference[i], axis=1)
            near = k_idx[np.argsort(d)[:3]]
            pred[i] = (pred[near] + s * (reference[i] - reference[near]) @ R.T).mean(0)
    return pred


def _plausible_jump(pred: np.ndarray, aligned: np.ndarray, dots: np.ndarray, gate: float, n_aligned: int,
                    share: float = 0.5) -> bool:
    """Whether the layout may move from ``pred (K, 2)`` to ``aligned (K, 2)``, which explains
    ``n_aligned`` of this frame's ``dots`` within ``gate``.

    A move within ``gate`` (median over the markers) is a correction of the motion prediction.
    A larger one is a jump of the whole face, which leaves few dots where the markers were
    predicted: it is refused when the prediction as it is still explains more than ``share`` as
    many markers as the move (the face did not jump; clutter lined up with part of the layout).
    Without this, a frame with a few markers hidden sent the alignment's search over all dot
    pairs onto clutter (teeth, nostrils, skin texture): on ``default`` validation seed 8 with the
    windowed dot fit, the direct view's layout moved 22 px (the nose 44 px) while the face moved
    2.5 px, and five markers were lost for the rest of the clip.
    """
    move = float(np.median(np.linalg.norm(aligned - pred, axis=1)))
    if move <= gate:
        return True
    still = int((assign(pred, dots, np.full(len(pred), gate)) >= 0).sum())
    return still <= share * n_aligned


def shift_group(pred: np.ndarray, dots: np.ndarray, gate: float, tol: float, reach: float,
                min_group: int = 3, share: float = 0.8) -> tuple[np.ndarray, np.ndarray]:
    """Move the markers that no dot explains by the one shift that puts them on the spare dots.

    A group of markers that jumped together beyond the search (the lower lip dropping) leaves
    its predictions on bare skin and its dots unclaimed; the similarity of :func:`predict`,
    fitted to all markers, does not follow it, and neither do the neighbours when the whole group
    went. The markers with no dot within ``gate`` of ``pred (P, 2)`` form the group, the dots
    farther than ``gate`` from every prediction are spare. Every offset up to ``reach`` from a
    group marker to a spare dot is a hypothesis; the one that puts most of the group within
    ``tol`` of a spare dot wins if it puts at least ``min_group`` markers and ``share`` of the
    group there and no other offset (``tol`` or more away) does as well. ``tol`` is tight, a
    dot's snap distance, and ``share`` high: a row of look-alike dots shifted by one spacing
    fits part of a group that did not move as one, and must not win. The moved markers should
    still pass the tracker's unambiguity test (they are guesses, not sightings).
    Returns (pred moved (P, 2), moved (P,) bool).
    """
    moved = np.zeros(len(pred), dtype=bool)
    ok = np.all(np.isfinite(pred), axis=1)
    if len(dots) < min_group or ok.sum() < min_group:
        return pred, moved
    d = np.linalg.norm(pred[:, None] - dots[None], axis=2)
    d[~ok] = np.inf
    group = np.flatnonzero(ok & (d.min(1) > gate))
    spare = dots[d.min(0) > gate]
    if len(group) < min_group or len(spare) < min_group:
        return pred, moved
    offsets = (spare[None] - pred[group][:, None]).reshape(-1, 2)
    offsets = offsets[np.linalg.norm(offsets, axis=1) <= reach]
    if len(offsets) == 0:
        return pred, moved
    to = pred[group][None, :, None] + offsets[:, None, None] - spare[None, None]    # (H, G, S, 2)
    hit = np.linalg.norm(to, axis=3).min(2) <= tol                                  # (H, G)
    count = hit.sum(1)
    best = int(np.argmax(count))
    rivals = np.linalg.norm(offsets - offsets[best], axis=1) >= tol
    if count[best] < max(min_group, share * len(group)) or (rivals & (count >= count[best])).any():
        return pred, moved
    on = group[hit[best]]
    near = np.linalg.norm(pred[on][:, None] + offsets[best] - spare[None], axis=2).argmin(1)
    out = pred.copy()
    out[group] += np.mean(spare[near] - pred[on], axis=0)
    moved[group] = True
    return out, moved


def fix_order(uv: np.ndarray, status: np.ndarray, reference: np.ndarray, radius: float) -> None:
    """Swap back pairs of close markers whose positions came out in the wrong order (in place).

    Two dots a few pixels apart can be exchanged by the assignment (each marker takes the
    other's dot); they then move together, so nothing later corrects it. For markers closer
    than ``radius`` in the reference layout, the vector between them keeps its direction under
    any plausible lip motion; a pair whose tracked vector points against the reference one is
    swapped.
    """
    seen = np.flatnonzero(status != LOST)
    if len(seen) < 2:
        return
    ref = reference[seen]
    d = np.linalg.norm(ref[:, None] - ref[None], axis=2)
    ii, jj = np.nonzero(np.triu(d < radius, 1))
    for a, b in zip(seen[ii[np.argsort(d[ii, jj])]], seen[jj[np.argsort(d[ii, jj])]], strict=True):
        if (uv[b] - uv[a]) @ (reference[b] - reference[a]) < 0:
            uv[[a, b]] = uv[[b, a]]


def drop_merged(uv: np.ndarray, status: np.ndarray, cand: np.ndarray, searched: np.ndarray,
                 radius: float) -> None:
    """Mark markers whose dots have merged as lost (in place).

    Two markers closer in the image than a dot's width give one blob: the assignment hands it
    to one of them and the other finds nothing, or only a correlation peak on the same blob.
    Neither position can be trusted then, so both are dropped: a marker that found no dot of its
    own (lost, or correlation only) and whose candidate lies within ``radius`` of a dot another
    marker took makes both lost.
    """
    own = np.isin(status, (TRACKED, RECOVERED))
    orphan = searched & ~own & np.all(np.isfinite(cand), axis=1)
    if not orphan.any() or not own.any():
        return
    d = np.linalg.norm(cand[orphan][:, None] - uv[own][None], axis=2)
    near = d < radius
    if near.any():
        status[np.flatnonzero(orphan)[near.any(1)]] = LOST
        status[np.flatnonzero(own)[near.any(0)]] = LOST
        uv[status == LOST] = np.nan


def carry_lost_markers(last: np.ndarray, before: np.ndarray, uv: np.ndarray, visible: np.ndarray,
                        neighbours: int = 6, shrink: float = 0.1) -> None:
    """Move the last-seen positions of lost markers with their nearest seen neighbours (in place).

    Without this a lost marker waits where it was last seen while the face moves on, and its
    search misses it when it reappears. ``before (P, 2)`` are the markers' positions before the
    image (seen or carried), ``uv (P, 2)`` and ``visible (P,)`` what it showed. Each marker not
    visible there moves as the displacements ``uv - before`` of its ``neighbours`` nearest visible
    markers say, by a local affine fit (weights 1 / (1 + distance)^2): local, so a lower-lip
    marker follows the lower lip when the jaw opens, and affine, so a marker between a lip corner
    that barely moved and a lip middle that dropped drops part of the way (a plain mean of the
    neighbours is off by half a jump). The fit's gradient is shrunk toward none by ``shrink`` of
    the neighbours' weighted spread, which keeps nearly collinear neighbours from extrapolating.
    A neighbour just re-acquired counts with its whole jump from where it was carried: when a
    group of markers jumps together and some are lost, the first found again tells where the
    others went. Updates ``last`` of the markers not visible.
    """
    ok = np.all(np.isfinite(before), axis=1)
    pairs = np.flatnonzero(visible & ok)
    lost = np.flatnonzero(~visible & ok)
    if len(lost) == 0 or len(pairs) == 0:
        return
    moves = uv[pairs] - before[pairs]
    k = min(neighbours, len(pairs))
    for i in lost:
        x = before[pairs] - before[i]
        near = np.argsort(np.linalg.norm(x, axis=1))[:k]
        x = x[near]
        w = 1.0 / (1.0 + np.linalg.norm(x, axis=1)) ** 2
        A = np.column_stack([np.ones(k), x])                       # move ~ c0 + x @ (c1, c2)
        lhs = A.T @ (w[:, None] * A)
        lhs[1:, 1:] += np.eye(2) * shrink * 0.5 * (w * (x * x).sum(1)).sum()
        last[i] = before[i] + np.linalg.lstsq(lhs, A.T @ (w[:, None] * moves[near]), rcond=None)[0][0]
