"""Forward-backward cross-check of the marker labels: the clip tracked a second time from its other end.

The tracker labels the dots once, where it starts (:mod:`lipgen.recon.anchor`), and carries the labels
from there; a label wrong at the start stays wrong for as long as the marker is followed, and the
3-D checks cannot always see it. On ``hard`` the layout at rest predicts a marker to about 2 mm while
the corner dots lie 4-5 mm apart: on 8 of 20 spent ``hard`` sets the first frame held a marker on a
wrong dot in both views (``lower_corner_left`` on ``corner_left``'s dot, whose own marker was never
seen, on ``hard`` 102), and the 3-D layout residual put the wrong label nearer than the right one.

A second run that starts from the clip's other end labels the dots afresh, from another frame. Where
the two runs both see a marker and put it on different dots, one of them is wrong (a tracking failure
detected by forward-backward consistency, after Kalal, Mikolajczyk and Matas, "Forward-backward error:
automatic detection of tracking failures", ICPR 2010). Where they agree, or only one sees the marker, the
first run's sighting stands.

* A dispute is judged over each marker's span of consecutive disputed frames (:func:`arbitrate`): the run
  whose triangulated points lie clearly nearer the marker's layout prediction wins.
* An undecided dispute is dropped in both views, or, with ``keep_undecided``, left to the first run: the
  first run starts at the clip's first complete frame or at frame 0, where the clips open near rest and
  labels are surer than at the last frame. Dropping every dispute lost on the development sets (``hard``
  90 and 102: the reversed run, wrong from frame 39, took the first run's right sightings with it).
* With ``fill``, a marker the first run does not have in both views takes the second run's pair, when that
  pair agrees with whatever the first run saw: the second run finds markers the first lost.

The pipeline's defaults (``ReconstructSettings.cross_check`` and its three options, all on) were chosen
on 18 development sets and passed held-out fresh sets (``renders/examples/tracking/xc27.md``).

The second run is :func:`lipgen.recon.anchor.track_from_anchor` on the clip reversed (its anchor the
last probed complete frame, counting from the end; the last frame when none is), so it costs one more
tracking of the clip.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import fields

import numpy as np

from lipgen.recon.anchor import TrackFn, anchor_line, track_from_anchor
from lipgen.recon.association import LOST
from lipgen.recon.continuity import continuity_verdict
from lipgen.recon.extend import extend_line
from lipgen.recon.gapfill import gap_fill_line
from lipgen.recon.nose import nose_line
from lipgen.recon.shareddot import shared_dot_line
from lipgen.recon.splitruns import split_runs_line
from lipgen.recon.tracks import Tracks, seen, true_runs

__all__ = ["reversed_run", "runs_agree", "arbitrate", "layout_residuals", "view_distances", "cross_check",
           "cross_check_line", "tracking_lines"]


def _reversed(tracks: Tracks) -> Tracks:
    def flip(a):
        return None if a is None else np.ascontiguousarray(a[::-1])   # rejected may be None

    return Tracks(**{f.name: flip(getattr(tracks, f.name)) for f in fields(Tracks)})   # as anchor.join_runs


def reversed_run(frame_at: Callable[[int], np.ndarray], n_frames: int, track: TrackFn,
                 step: int | None, progress: Callable[[int], None] | None = None
                 ) -> tuple[tuple[Tracks, Tracks], dict]:
    """The clip tracked from its other end (see the module docstring), in time order.

    Parameters
    ----------
    frame_at, n_frames, track, step, progress
        As :func:`lipgen.recon.anchor.track_from_anchor` (``progress`` is called once per frame tracked,
        with the index in the reversed clip).

    Returns
    -------
    (virtual, real) : Tracks
        Frames 0 ... F - 1.
    record : dict
        The anchor record of the reversed clip, with ``frame`` counted in the clip's own time.
    """
    (virtual, real), record = track_from_anchor(lambda i: frame_at(n_frames - 1 - i), n_frames, track, step,
                                                progress)
    return (_reversed(virtual), _reversed(real)), record | {"frame": n_frames - 1 - int(record["frame"])}


def _compare(first: tuple[Tracks, Tracks], second: tuple[Tracks, Tracks], tol: float
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each run's seen masks and the runs' distances, (2, F, P) each; ``tol`` and the shapes checked."""
    if not tol > 0:
        raise ValueError(f"tol must be a positive distance in pixels, got {tol!r}")
    for a, b in zip(first, second, strict=True):
        if a.uv.shape != b.uv.shape:
            raise ValueError(f"the two runs' tracks differ in shape: {a.uv.shape} and {b.uv.shape}")
    seen_a = np.stack([seen(t) for t in first])
    seen_b = np.stack([seen(t) for t in second])
    dist = np.stack([np.linalg.norm(a.uv - b.uv, axis=-1) for a, b in zip(first, second, strict=True)])
    return seen_a, seen_b, dist


def runs_agree(first: tuple[Tracks, Tracks], second: tuple[Tracks, Tracks], tol: float) -> np.ndarray:
    """Where two tracking runs put a marker on the same dot in both views: among the markers both runs
    see in both views, those :func:`cross_check` does not dispute.

    Parameters
    ----------
    first, second : (virtual, real) Tracks
        The same clip, each (F, P).
    tol : float
        Pixels: sightings nearer than this are one dot.

    Returns
    -------
    (F, P) bool
        Both runs see the marker in both views, within ``tol`` of each other in each.
    """
    seen_a, seen_b, dist = _compare(first, second, tol)
    with np.errstate(invalid="ignore"):
        return (seen_a & seen_b & (dist <= tol)).all(axis=0)


def arbitrate(first: tuple[Tracks, Tracks], second: tuple[Tracks, Tracks], disputed: np.ndarray, cameras,
              rest_points, covariance=None, ratio: float = 0.6, pairs: bool = False,
              spread: bool = False, continuity: bool = False) -> np.ndarray:
    """Which run holds a disputed marker's right dot, judged over each run of consecutive disputed frames.

    In every disputed frame both runs' pairs are triangulated and compared with the marker's position
    predicted from the undisputed markers of the first run (:func:`lipgen.recon.firstframe.predict_layout`,
    the physics prior with ``covariance``). Over the span, the run whose points lie nearer the prediction
    on average wins when it is nearer than ``ratio`` times the other (the first frame's replacement rule);
    otherwise neither does.

    With ``spread`` (and ``covariance``), a run's distance from the prediction is measured against the
    prediction's own spread (the physics prior conditioned on the other markers; a Mahalanobis distance),
    not in mm: the prior knows in which directions a marker moves freely, as a corner does along the
    mouth's width.

    With ``pairs``, a disputed frame the layout could not judge in 3-D, because only one run sees the marker
    in both views, is judged in 2-D (:func:`_pair_over_single`): that run's pair wins where its sighting
    lies nearer the prediction's projection than ``ratio`` times the other run's, in the view(s) the other
    run sees. A sighting in one view is never accepted on its own; the pair's rays are checked later.
    Frames without a prediction, and frames the layout judged in 3-D, keep the span's verdict.

    With ``continuity``, a span where one run's sightings at its ends clearly continue the motion both runs
    agreed on just outside it goes to that run, whatever the layout says
    (:func:`lipgen.recon.continuity.continuity_verdict`, at the same ``ratio``); the layout judges the rest.

    Parameters
    ----------
    first, second : (virtual, real) Tracks
    disputed : (F, P) bool
    cameras : (virtual, real) PinholeCamera
    rest_points : (P, 3) float
        The markers at rest in the frame of ``cameras``, mm.
    covariance : (3P, 3P) float, optional
    ratio : float
    pairs, spread, continuity : bool

    Returns
    -------
    (F, P) int8
        0 where neither run is trusted, 1 where the first run's sighting stands, 2 where the second's.
    """
    ra, rb, predicted, both_a, both_b = layout_residuals(first, second, disputed, cameras, rest_points,
                                                         covariance, spread)
    F, P = disputed.shape
    out = np.zeros((F, P), np.int8)
    for m in range(P):
        for start, stop in true_runs(disputed[:, m]):
            ok = np.isfinite(ra[start:stop, m]) & np.isfinite(rb[start:stop, m])
            if not ok.any():
                continue
            a, b = ra[start:stop, m][ok].mean(), rb[start:stop, m][ok].mean()
            out[start:stop, m] = 2 if b < ratio * a else 1 if a < ratio * b else 0
    if continuity:
        carried = continuity_verdict(first, second, disputed, ratio)
        out = np.where(carried != 0, carried, out).astype(np.int8)
    if pairs:
        unjudged = disputed & ~(np.isfinite(ra) & np.isfinite(rb)) & (out == 0)
        out[unjudged] = _pair_over_single(first, second, unjudged, both_a, both_b, predicted, cameras, ratio)
    return out


def layout_residuals(first: tuple[Tracks, Tracks], second: tuple[Tracks, Tracks], disputed: np.ndarray,
                     cameras, rest_points, covariance=None, spread: bool = False):
    """:func:`arbitrate`'s figures: each run's 3-D distance from the layout's prediction, disputed frames.

    Returns
    -------
    ra, rb : (F, P) float
        mm from the prediction of the first and second run's triangulated pair (with ``spread`` and
        ``covariance``: in units of the prediction's spread, up to a common scale); NaN where the run has no
        pair or the frame no prediction (fewer than 6 undisputed markers the first run sees in both views).
    predicted : (F, P, 3) float
        The prediction, mm in the frame of ``cameras``; NaN in frames without one.
    both_a, both_b : (F, P) bool
        Where each run sees the marker in both views.
    """
    from lipgen.recon.firstframe import predict_layout
    from lipgen.recon.layoutprior import predict_layout_physics
    from lipgen.recon.pointreg import layout_spacing
    from lipgen.rig.pinhole import triangulate

    rest = np.asarray(rest_points, dtype=float)
    width = layout_spacing(rest[np.all(np.isfinite(rest), axis=1)])

    def points(run):
        both = seen(run[0]) & seen(run[1])
        X = np.full(both.shape + (3,), np.nan)
        X[both] = triangulate(cameras[1], run[1].uv[both], cameras[0], run[0].uv[both])[0]
        return X, both

    Xa, both_a = points(first)
    Xb, both_b = points(second)
    F, P = disputed.shape
    ra, rb = np.full((F, P), np.nan), np.full((F, P), np.nan)
    predicted = np.full((F, P, 3), np.nan)
    for f in np.flatnonzero(disputed.any(axis=1)):
        use = both_a[f] & ~disputed[f]
        if use.sum() < 6:
            continue
        if spread and covariance is not None:
            predicted[f], loose = predict_layout_physics(rest, Xa[f], use, covariance, spread=True)
            for X, r in ((Xa, ra), (Xb, rb)):
                for m in np.flatnonzero(disputed[f] & np.all(np.isfinite(X[f]), axis=1)):
                    d = X[f, m] - predicted[f, m]
                    r[f, m] = np.sqrt(d @ np.linalg.solve(loose[m], d))
            continue
        predicted[f] = predict_layout(rest, Xa[f], use, width, covariance)
        ra[f] = np.linalg.norm(Xa[f] - predicted[f], axis=1)
        rb[f] = np.linalg.norm(Xb[f] - predicted[f], axis=1)
    return ra, rb, predicted, both_a, both_b


def view_distances(pair: tuple[Tracks, Tracks], single: tuple[Tracks, Tracks], f: int, m: int,
                   target: np.ndarray, cameras) -> tuple[float, float]:
    """Mean pixels from the projection of ``target`` (3,) mm to marker ``m``'s sightings in frame ``f``: the
    ``single`` run's and the ``pair`` run's, over the views the single run sees (:func:`arbitrate`'s
    ``pairs``)."""
    near = []
    for v, cam in enumerate(cameras):
        if np.all(np.isfinite(single[v].uv[f, m])):
            at = cam.project(np.asarray(target, float)[None])[0]
            near.append((np.linalg.norm(single[v].uv[f, m] - at), np.linalg.norm(pair[v].uv[f, m] - at)))
    d_single, d_pair = np.mean(near, axis=0)
    return float(d_single), float(d_pair)


def _pair_over_single(first, second, frames, both_a, both_b, predicted, cameras, ratio: float) -> np.ndarray:
    """For ``arbitrate``'s ``pairs``: at each (frame, marker) of ``frames`` (F, P) bool, the run (1 or 2)
    that alone has a pair there, where the pair's sightings lie nearer than ``ratio`` times the other run's
    to the projection of ``predicted`` (F, P, 3) mm (:func:`view_distances`); else 0. Returns the verdicts
    at ``frames``, in its order."""
    out = []
    for f, m in np.argwhere(frames):
        if both_a[f, m] == both_b[f, m] or not np.all(np.isfinite(predicted[f, m])):
            out.append(0)
            continue
        pair, single = (first, second) if both_a[f, m] else (second, first)
        d_single, d_pair = view_distances(pair, single, f, m, predicted[f, m], cameras)
        out.append(0 if not d_pair < ratio * d_single else 1 if both_a[f, m] else 2)
    return np.asarray(out, np.int8)


def cross_check(first: tuple[Tracks, Tracks], second: tuple[Tracks, Tracks], tol: float,
                fill: bool = False, judge=None, keep_undecided: bool = False
                ) -> tuple[tuple[Tracks, Tracks], dict]:
    """Drop the sightings the two runs put on different dots; optionally fill from the second run.

    Parameters
    ----------
    first, second : (virtual, real) Tracks
        The same clip tracked twice (F frames, P markers each).
    tol : float
        Two sightings of one marker in one view farther apart than this (pixels) are on different dots.
    fill : bool
        Where the first run lacks a marker in a view (after the drop) and the second run has it in both
        views, agreeing with the first run's sighting in the other view if it has one, take the second
        run's pair.
    judge : callable, optional
        ``judge(first, second, disputed)`` -> (F, P) int8 as :func:`arbitrate`: where it says 1 the first
        run's sighting stands, where 2 the second run's pair is taken; elsewhere both are dropped.
    keep_undecided : bool
        Where the runs disagree and no judge (or an undecided one) settles it, the first run's sighting
        stands instead of being dropped (the first run starts nearer rest, where labels are surer).

    Returns
    -------
    (virtual, real) : Tracks
        The first run's tracks with the dropped disagreements taken back in both views (``LOST``,
        ``rejected``), the judge's swaps made and, with ``fill``, the second run's sightings added.
    record : dict
        Frame-marker pairs ``dropped``, ``kept`` (disputed, the first run's), ``swapped`` (disputed, the
        second run's) and ``filled``; and ``tol``.
    """
    seen_a, seen_b, dist = _compare(first, second, tol)
    with np.errstate(invalid="ignore"):
        differ = seen_a & seen_b & (dist > tol)          # (2, F, P)
    drop = differ.any(axis=0)                            # (F, P): one view's disagreement is the pair's
    verdict = np.zeros(drop.shape, np.int8)
    if judge is not None and drop.any():
        verdict = np.where(drop, np.asarray(judge(first, second, drop), np.int8), 0)
    if keep_undecided:
        verdict = np.where(drop & (verdict == 0), 1, verdict).astype(np.int8)
    swap = verdict == 2
    drop = drop & (verdict == 0)
    keep = seen_a & ~drop
    take = np.zeros_like(drop)
    if fill:
        agree = ~seen_a | (dist <= tol)
        take = ~keep.all(axis=0) & seen_b.all(axis=0) & ~drop & agree.all(axis=0)
    from_b = take | swap                                 # (F, P): the second run's pair, both views
    out = []
    for v, (a, b) in enumerate(zip(first, second, strict=True)):
        uv, status, score = a.uv.copy(), a.status.copy(), a.score.copy()
        rejected = np.zeros(status.shape, bool) if a.rejected is None else a.rejected.copy()
        gone = drop & seen_a[v]
        uv[gone], status[gone], rejected[gone] = np.nan, LOST, True
        uv[from_b], status[from_b], score[from_b] = b.uv[from_b], b.status[from_b], b.score[from_b]
        rejected[from_b] = swap[from_b] & (a.status[from_b] != LOST)   # a swapped-out sighting was taken back
        out.append(Tracks(uv=uv, visible=(status != LOST), status=status, score=score, rejected=rejected))
    record = {"dropped": int(drop.sum()), "filled": int(take.sum()), "tol": float(tol),
              "kept": int((verdict == 1).sum()), "swapped": int(swap.sum())}
    return (out[0], out[1]), record


def cross_check_line(record: dict | None) -> str | None:
    """One sentence saying what the second tracking run changed, for the command's output; None when the
    clip was tracked once (``record`` None: ``cross_check`` off, or a reconstruction made before it)."""
    if not record:
        return None
    disputed = record["kept"] + record["swapped"] + record["dropped"]
    start = record.get("anchor", {}).get("frame")
    where = "" if start is None else f", in reverse from frame {start}"
    return (f"Tracked a second time{where}: the two runs put {disputed} marker sighting(s) on different dots "
            f"({record['kept']} kept from the first run, {record['swapped']} taken from the second, "
            f"{record['dropped']} dropped); {record['filled']} sighting(s) the first run lacked were filled "
            "from the second.")


def tracking_lines(info: dict) -> list[str]:
    """The sentences on where tracking started, what its second run changed, which markers shared a dot,
    which tracks were split, what the gap fill and the walk-on added and where the nose was found again
    (:func:`anchor_line`, :func:`cross_check_line`, :func:`lipgen.recon.shareddot.shared_dot_line`,
    :func:`lipgen.recon.splitruns.split_runs_line`,
    :func:`lipgen.recon.gapfill.gap_fill_line`, :func:`lipgen.recon.extend.extend_line`,
    :func:`lipgen.recon.nose.nose_line`) for a
    reconstruction's ``info``, the ones that apply: for
    ``lipgen reconstruct``'s output and ``lipgen evaluate``'s report."""
    names = [*info.get("marker_names", []), "nose"]
    lines = (anchor_line(info.get("tracking_anchor")), cross_check_line(info.get("cross_check")),
             shared_dot_line(info.get("shared_dots"), names), split_runs_line(info.get("split_runs")),
             gap_fill_line(info.get("gap_fill")),
             extend_line(info.get("walk_on")), nose_line(info.get("nose")))
    return [line for line in lines if line]
