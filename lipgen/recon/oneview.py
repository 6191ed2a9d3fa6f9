"""Sightings seen in one view only, paired with the other view's dot where the 3-D layout puts the marker.

A marker seen in one view (A) and not in the other (B) is never triangulated, so nothing checks
it, and B acquires it only by its own 2-D layout rules (:func:`lipgen.recon.acquire.acquire_layout`),
which refuse a dot when a neighbour's placed position is nearly as near (``upper_mid`` and
``bow_dip`` are 4-5 px apart on ``hard``). On ``hard`` validation seed 10 the mirror acquired
``bow_dip`` on its dot (0.2 px) at frame 5, the direct view never did (its dot detected 0.2-0.3
px from the truth), and the pending acquisition (:mod:`lipgen.recon.pending`) expired: the marker
was never accepted. And a one-view track on another marker's dot blocks that marker: the other
view's acquisition of it misses the track's ray and is withdrawn
(:func:`lipgen.recon.viewcheck.confirm_acquired`), every frame (``hard`` 7: the direct view's
right ``upper_mid`` 9 times, and 2 pending ones erased).

Multi-camera marker labelling settles a 2-D label by the other camera's epipolar line and the
template placed by the labelled markers. :func:`pair_one_view` does that every frame for each
marker ``k`` whose sighting in A is an *acquisition* (this frame's, or a pending one: its
identity came from A's layout rules) and which B does not see, or sees on a sighting that was
never confirmed by A:

* the markers seen in both views (rays within the gap limit; at least ``min_confirmed``) predict
  ``k``'s 3-D point by the layout at rest, a 3-D similarity and their smooth offsets
  (:func:`lipgen.recon.firstframe.predict_layout`);
* B's round dots whose rays meet A's ray of ``k`` give candidate points; a dot held by a marker
  seen in both views, by one whose current run in B was ever confirmed, or by another
  acquisition is not a candidate;
* the nearest candidate is taken when it is within ``near`` spacings of the prediction,
  unambiguous (nearer than ``ratio`` times the next candidate), nearer ``k``'s prediction than
  any other unconfirmed marker's (the rule of :func:`lipgen.recon.grow.grow_first_frame`), about
  as dark as B's markers' dots, and, in B's image, within the acquisition gate of where B's
  layout registered to the confirmed markers puts ``k`` and nearer it than ``ratio`` times any
  other unconfirmed marker's placement;
* B then takes the dot for ``k`` (:meth:`lipgen.recon.track.MarkerTracker.take`). A marker whose
  never-confirmed one-view track in B held the dot is taken back there and forgotten
  (:meth:`~lipgen.recon.track.MarkerTracker.unlearn`), so its own dot is acquired afresh.

The new pair then passes the ordinary checks (ray gap, 3-D step, the motion check's judgement of
a new run), as any re-acquired sighting. A one-view track that merely continues is never the
source of a pairing: on ``hard`` 7 the mirror's ``bow_dip`` slid onto ``upper_mid``'s dot at
frame 1, and pairing from it (tried first) put ``bow_dip`` on ``upper_mid``'s point in both views
(78 accepted sightings over 3 px): the 3-D layout, 2-5 mm off on ``hard``, cannot tell two
markers 4 mm apart. So on ``hard`` 7 only the direct view's acquisition of ``upper_mid`` from
frame 31 on releases the mirror's ``bow_dip`` (4 frames gained of that seed's 40); from frame 16
to 28 the same right acquisitions were refused, their point lying nearer ``bow_dip``'s 3-D
prediction than ``upper_mid``'s.

Measured with ``TrackerSettings.max_strength_ratio`` (the two together; calibrate, track,
triangulate with cached calibrations, 40 frames, scored against the truth; accepted share of the
visible sightings / accepted within 3 px / accepted sightings over 3 px in both views; main
8e34732 -> branch; load 4-9):

* validation ``hard`` 7 / 8 / 10 / 21 / 22: 71.6 / 83.1 / 70.8 / 50.7 / 87.2 -> 72.2 / 83.2 /
  77.9 / 55.9 / 85.3 %; within 3 px 71.4 / 83.0 / 69.6 / 46.2 / 85.4 -> 72.0 / 83.1 / 77.9 /
  50.8 / 85.3 %; over 3 px 2 / 1 / 16 / 61 / 25 -> 2 / 1 / 0 / 69 / 0 (105 -> 72). ``hard`` 10:
  ``bow_dip`` accepted in 35 of 40 frames (0 before). ``hard`` 21: ``upper_corner_left``, a
  first-frame match on a lure of about the ink's darkness, is kept longer (44 -> 58 over 3 px).
  ``default`` 8 and ``easy`` 7 unchanged (98.0 and 99.9 %, none over 3 px).
* The darkness limit alone: ``hard`` 10 / 22 over 3 px 16 / 25 -> 0 / 0, accepted share 70.8 /
  85.3 %; ``hard`` 7 unchanged; ``hard`` 21 49.3 %, 59 over 3 px.
* Held out (run once, after the freeze; ``hard`` 23 and 24 new): ``hard`` 11 / 23 / 24 72.8 /
  89.3 / 83.8 -> 72.8 / 89.3 / 90.1 %, over 3 px 2 / 4 / 4 -> 2 / 4 / 4; ``default`` 11 99.1 %
  either way, none over 3 px.
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen._validate import as_float_array
from lipgen.recon.acquire import place_layout
from lipgen.recon.dots import ink_gray
from lipgen.recon.firstframe import predict_layout
from lipgen.recon.pointreg import layout_spacing
from lipgen.recon.track import LOST, MarkerTracker
from lipgen.rig.camera import VIEWS
from lipgen.rig.pinhole import triangulate

__all__ = ["pair_one_view", "confirmed_runs"]

log = logging.getLogger(__name__)


def confirmed_runs(trackers: list[MarkerTracker]) -> np.ndarray:
    """Per view and marker: its current run in that view was seen in both views in an earlier frame.

    A sighting in both views that survived that frame's view checks had rays that met.

    Parameters
    ----------
    trackers : (virtual, real) MarkerTracker

    Returns
    -------
    (2, P) bool
        False where the marker is lost in that view now, or its run there never had the other
        view's sighting in the same frame before this one.
    """
    P = len(trackers[0].init)
    out = np.zeros((2, P), dtype=bool)
    for v in range(2):
        alive = trackers[v]._out[-1][1] != LOST
        for t in range(len(trackers[v]._out) - 1, -1, -1):
            st_v, st_o = trackers[v]._out[t][1], trackers[1 - v]._out[t][1]
            alive &= st_v != LOST
            if not alive.any():
                break
            out[v] |= alive & (st_o != LOST) & (t < len(trackers[v]._out) - 1)
            if not (alive & ~out[v]).any():
                break  # every run still alive is confirmed: older frames change nothing (else O(F^2))
    return out


def pair_one_view(
    trackers: list[MarkerTracker],
    views,
    cameras,
    rest_points,
    max_gap: float,
    fresh=None,
    near: float = 0.8,
    ratio: float = 0.6,
    min_confirmed: int = 8,
    max_dark: float = 1.5,
    names=None,
) -> np.ndarray:
    """Pair markers seen in one view only with the other view's dot where the layout puts them.

    The trackers are changed in place.

    Call after both trackers' :meth:`~lipgen.recon.track.MarkerTracker.step` on one image pair
    and before the view checks (:func:`lipgen.recon.viewcheck.check_views`).

    Parameters
    ----------
    trackers : (virtual, real) MarkerTracker
    views : (virtual, real) images
        This image pair, as given to the trackers (for the templates of the dots taken).
    cameras : (virtual, real) PinholeCamera
    rest_points : (P, 3) float
        The markers at rest in the frame of ``cameras``, mm (NaN rows: markers without a layout).
    max_gap : float
        The ray-gap limit now, mm.
    fresh : (2, P) bool, optional
        The one-view sightings that may be paired: acquisitions (this image's, or pending ones,
        :class:`lipgen.recon.pending.PendingAcquisitions`), whose identity the view's layout
        gave unambiguously. A track that continues may have slid onto a neighbour's dot (the
        mirror's ``bow_dip`` onto ``upper_mid``'s on ``hard`` 7), and the 3-D layout, a weak
        prior on ``hard``, would then carry the mistake into the other view. None: all.
    near : float
        Largest distance from the prediction to the candidate point, in layout spacings.
    ratio : float
        Ambiguity ratio (see the module's description).
    min_confirmed : int
        Fewest markers seen in both views now to predict from (the motion check's
        ``min_established``: with fewer the layout predicts the lips 7-9 mm off on ``hard`` 21).
    max_dark : float
        Greatest darkness of the dot, as a share of the median of the view's markers' dots (at
        least ``TrackerSettings.min_strength_ratio`` of it). Tighter than an acquisition's
        ``TrackerSettings.max_strength_ratio`` (2): a pairing takes a dot the view itself did not
        choose, on the other view's word alone.
    names : sequence of str, optional
        Marker names, for the log.

    Returns
    -------
    (2, P) bool
        The sightings set per view (the dots taken, and the markers taken back for them).
    """
    P = len(trackers[0].init)
    rest = as_float_array(rest_points, "rest_points", (P, 3), finite=False)
    if fresh is not None and np.shape(fresh) != (2, P):
        raise ValueError(
            f"fresh must be a (2, {P}) bool array (per view and marker), got shape {np.shape(fresh)}"
        )
    if not (0 < ratio <= 1 and near > 0 and max_dark > 0):
        raise ValueError(
            f"near and max_dark must be positive and ratio in (0, 1], got {near!r}, {max_dark!r}, {ratio!r}"
        )
    if missing := [VIEWS[v] for v in range(2) if trackers[v].reference is None]:
        raise ValueError(
            f"the {' and '.join(missing)} view's tracker has no reference_uv (the markers' "
            "expected layout): make it with MarkerTracker(..., reference_uv=...)"
        )
    changed = np.zeros((2, P), dtype=bool)
    if len(trackers[0]._out) < 2:
        return changed
    uv = [tr._out[-1][0] for tr in trackers]
    seen = np.stack([tr._out[-1][1] != LOST for tr in trackers]) & ~np.stack([tr.twins for tr in trackers])
    valid = np.all(np.isfinite(rest), axis=1)
    both = seen.all(0) & valid
    X = np.full((P, 3), np.nan)
    gap = np.full(P, np.inf)
    if both.any():
        X[both], gap[both] = triangulate(cameras[1], uv[1][both], cameras[0], uv[0][both])
    ok = both & (gap <= max_gap)
    if ok.sum() < min_confirmed:
        return changed
    spacing = layout_spacing(rest[valid])
    pred = predict_layout(np.where(valid[:, None], rest, 0.0), np.where(ok[:, None], X, 0.0), ok, spacing)
    # A marker far from every other (the nose) is not predicted by their offsets: not paired.
    dist = np.linalg.norm(rest[:, None] - rest[None], axis=2)
    np.fill_diagonal(dist, np.inf)
    dist[:, ~valid] = np.inf
    pending = valid & ~ok & np.all(np.isfinite(pred), axis=1) & (dist.min(1) <= 2.5 * spacing)
    confirmed = confirmed_runs(trackers)
    fresh = np.ones((2, P), dtype=bool) if fresh is None else np.asarray(fresh, dtype=bool)
    plans = {}
    for k in np.flatnonzero(pending):
        for a in range(2):  # A sees k; B is searched for k's dot
            b = 1 - a
            if not seen[a, k] or (seen[b, k] and confirmed[b, k]) or not fresh[a, k]:
                continue
            got = _partner(
                trackers[b],
                cameras,
                a,
                uv[a][k],
                pred,
                k,
                pending,
                ok,
                uv[b],
                seen[b],
                confirmed[b],
                fresh[b],
                max_gap,
                near * spacing,
                ratio,
                max_dark,
            )
            if got is not None:
                plans.setdefault(k, []).append((b, got))
    # (view, marker) given a dot this frame: a holder that takes a dot of its own is not released
    # (released after its own take, it would lose that take)
    takes = {(f[0][0], k) for k, f in plans.items() if len(f) == 1}
    for k, found in plans.items():
        if len(found) != 1:
            continue  # each view's sighting finds a partner: which is right is unknown
        b, (p, holder) = found[0]
        tb = trackers[b]
        if holder >= 0 and holder != k and (b, holder) not in takes:
            tb.reject([holder])
            tb.unlearn(holder)
            changed[b, holder] = True
        d, s = tb.dot_history[-1]
        tb.take(int(k), p, ink_gray(views[b]), float(s[np.argmin(np.linalg.norm(d - p, axis=1))]))
        changed[b, k] = True
        log.info(
            "frame %d: %s seen in the %s view only: paired with the %s view's dot where the 3-D layout "
            "puts it%s",
            len(tb._out) - 1,
            k if names is None else names[k],
            VIEWS[1 - b],
            VIEWS[b],
            ""
            if holder < 0 or holder == k
            else f" (taken from {holder if names is None else names[holder]}, seen there only)",
        )
    return changed


def _partner(
    tb: MarkerTracker,
    cameras,
    a: int,
    uv_a: np.ndarray,
    pred: np.ndarray,
    k: int,
    pending: np.ndarray,
    ok: np.ndarray,
    uv_b: np.ndarray,
    seen_b: np.ndarray,
    confirmed_b: np.ndarray,
    fresh_b: np.ndarray,
    max_gap: float,
    near: float,
    ratio: float,
    max_dark: float,
):
    """View B's dot for marker ``k`` seen in view A at ``uv_a``: ``(dot (2,), holder)`` or None.

    ``holder`` is the marker holding the dot in B (-1: free)."""
    dots = tb.dot_history[-1][0]
    if len(dots) == 0:
        return None
    ray = np.repeat(uv_a[None], len(dots), 0)
    if a == 0:
        pts, g = triangulate(cameras[1], dots, cameras[0], ray)
    else:
        pts, g = triangulate(cameras[1], ray, cameras[0], dots)
    holder = np.full(len(dots), -1)
    sep = tb.cfg.dots.separation / 2
    for j in np.flatnonzero(seen_b):
        dist = np.linalg.norm(dots - uv_b[j], axis=1)
        i = int(dist.argmin())
        if dist[i] < sep:
            holder[i] = j
    usable = g <= max_gap
    # A dot held by a marker seen in both views, by one confirmed in its run, or by a fresh
    # acquisition (two acquisitions in conflict: which is right is unknown) is not free.
    busy = (holder >= 0) & (holder != k)
    busy[busy] = ok[holder[busy]] | confirmed_b[holder[busy]] | fresh_b[holder[busy]]
    usable &= ~busy
    idx = np.flatnonzero(usable)
    if len(idx) == 0:
        return None
    d = np.linalg.norm(pts[idx] - pred[k], axis=1)
    o = np.argsort(d)
    best, dk = idx[o[0]], float(d[o[0]])
    if dk > near or (len(o) > 1 and dk >= ratio * d[o[1]]):
        return None
    others = np.flatnonzero(pending)
    others = others[others != k]
    d_other = np.linalg.norm(pred[others] - pts[best], axis=1).min() if len(others) else np.inf
    typ = tb.typical_strength(seen_b)
    log.debug(
        "pair %d view %d frame %d: dot %.2f %.2f, %.2f mm from the prediction, next marker %.2f, "
        "next dot %.2f, strength %.2f",
        k,
        1 - a,
        len(tb._out) - 1,
        *dots[best],
        dk,
        d_other,
        d[o[1]] if len(o) > 1 else np.inf,
        tb.dot_history[-1][1][best] / typ,
    )
    # As dark as the markers' dots: a fainter blob is skin texture, a much darker one the mouth's
    # inside at a lip corner.
    if d_other <= dk or not tb.cfg.min_strength_ratio * typ <= tb.dot_history[-1][1][best] <= max_dark * typ:
        return None
    # In B's image too, the dot must be nearer k than any marker not seen in both views, where the
    # layout registered to the markers seen in both puts them (a 4 mm mistake of the 3-D layout
    # along the lip's midline is a few pixels in one view and a marker in the other).
    placed = place_layout(tb.reference, np.where(ok[:, None], uv_b, 0.0), ok)
    rivals = np.flatnonzero(~ok & ~tb.twins)
    d2 = np.linalg.norm(placed[rivals] - dots[best], axis=1)
    own = float(np.linalg.norm(placed[k] - dots[best]))
    if own > tb.cfg.acquire_gate or (d2[rivals != k] * ratio <= own).any():
        return None
    return dots[best], int(holder[best])
