"""From raw camera-mirror frames to displacement fields of the model (thesis ch. 3 and §4.1).

The steps, each a small function so that tests and the evaluation can score them one by one:

1. :func:`track_raw_frames`: split every raw frame into its (virtual, real) views, match the
   first frame's dots to the markers' expected positions (replacing the thesis's GUI), and
   track them with normalised correlation (:class:`lipgen.recon.track.MarkerTracker`), both views in
   lock-step so each raw frame is read once. With the calibrated cameras, a sighting the other
   view contradicts (rays more than ``max_ray_gap`` apart) is taken back in the tracker, so a
   wrong dot is not followed. What later frames show is carried back: a marker first seen late
   is tracked back to the frames before (:mod:`lipgen.recon.backfill`), one found again is walked
   back until the history agrees, and a marker the 3-D layout check gives another dot on
   several frames in a row is re-tracked from there (:mod:`lipgen.recon.recheck`).
2. :func:`triangulate_tracks`: the closest point between the two rays of each marker (thesis
   Fig 3-5); a marker seen in one view only, or whose rays pass far apart (a mis-track), is
   marked not visible.
3. :func:`lipgen.recon.normalize.normalize_markers`: nose, lip planes, one similarity to the model.
4. :func:`reach_fields`: per frame, the least-strain field of the model that reaches the
   visible markers' goals (eq 4.3); frames are grouped by which markers they see, so each
   group costs one precomputation and one matrix product.

The whole run is :func:`lipgen.recon.pipeline.reconstruct_dataset`; this module does not know about
datasets on disk.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable

import numpy as np

from lipgen._validate import as_float_array
from lipgen.recon.backfill import WalkQueue
from lipgen.recon.epipolar import recover_along_epipolar
from lipgen.recon.firstpose import first_frame
from lipgen.recon.jumps import StepLimit
from lipgen.recon.motioncheck import MotionCheck
from lipgen.recon.oneview import pair_one_view
from lipgen.recon.outofplace import take_back_out_of_place
from lipgen.recon.pending import PendingAcquisitions
from lipgen.recon.recheck import IdentityCheck
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.shifted import ShiftCheck
from lipgen.recon.track import LOST, MarkerTracker, Tracks
from lipgen.recon.twins import resolve_twins
from lipgen.recon.viewcheck import check_views, confirm_blobs
from lipgen.rig.camera import VIEWS, MirrorRig
from lipgen.rig.pinhole import PinholeCamera, triangulate

__all__ = ["track_raw_frames", "triangulate_tracks", "triangulate_within_limit", "reach_fields",
           "expected_projections"]

log = logging.getLogger(__name__)


def expected_projections(views: tuple[PinholeCamera, PinholeCamera], points) -> np.ndarray:
    """(2, P, 2) pixels of world ``points (P, 3)`` in the (virtual, real) views."""
    X = as_float_array(points, "points", (None, 3))
    return np.stack([cam.project(X) for cam in views])


def track_raw_frames(raw_frames: Iterable, layout: MirrorRig, expected,
                     settings: ReconstructSettings = ReconstructSettings(),
                     progress: Callable[[int], None] | None = None,
                     cameras: tuple[PinholeCamera, PinholeCamera] | None = None,
                     names=None, rest_points=None, layout_covariance=None) -> tuple[Tracks, Tracks]:
    """Detect and track the markers in both views of a raw sequence.

    Parameters
    ----------
    raw_frames : iterable of (H, W[, 3]) arrays
        Raw camera-mirror frames in order (read one at a time).
    layout : MirrorRig
        Used only to split the raw frames into views.
    expected : (2, P, 2) float
        Rough marker positions in the (virtual, real) views, e.g. the projections of the
        model's markers at rest through the calibrated cameras; only their layout matters.
    settings : ReconstructSettings
    progress : callable, optional
        Called with the frame index after each frame.
    cameras : (virtual, real) PinholeCamera, optional
        The calibrated views. With them, a first-frame match whose two rays pass farther apart
        than ``settings.max_ray_gap`` is dropped in both views (one of the two is another
        marker's dot or no marker's); the tracker acquires the marker later from the layout,
        and every acquisition stands only when the other view confirms it
        (:func:`lipgen.recon.viewcheck.check_views`).
    names : sequence of str, optional
        Marker names, for the log.
    rest_points : (P, 3) float, optional
        The markers at rest in the frame of ``cameras`` (what ``expected`` projects). With them,
        ``cameras`` and ``settings.first_frame_lures``, the first frame's dots that no dot of the
        other view places near the layout in 3-D (the nose's shadow, tooth gaps) are not matched
        (:func:`lipgen.recon.stereo_init.layout_dots`).
    layout_covariance : (3P, 3P) float, optional
        The physics prior of ``rest_points``' layout
        (:func:`lipgen.recon.layoutprior.physics_layout_covariance`), for the 3-D layout checks of
        the first frame and of the identity re-check; None: their Gaussian-weighted offsets.

    Returns
    -------
    (virtual, real) : Tracks
    """
    exp = as_float_array(expected, "expected", (2, None, 2), finite=False)
    if layout_covariance is not None:
        if rest_points is None:
            raise ValueError("layout_covariance needs rest_points (the layout it is the prior of)")
        n = 3 * len(rest_points)
        layout_covariance = as_float_array(layout_covariance, "layout_covariance", (n, n))
    trackers: list[MarkerTracker] = []
    gap_limit = None if cameras is None else settings.ray_gap_limit(cameras)
    last3d = np.full((exp.shape[1], 3), np.nan)      # each marker's last accepted point (lab, mm)
    since = np.ones(exp.shape[1])                    # frames since then
    steps = None if settings.step_k is None else StepLimit(exp.shape[1], settings.step_k,
                                                           floor=settings.min_step)
    walks = (WalkQueue(exp.shape[1], settings.walk_frames)
             if cameras is not None and (settings.backfill or settings.rewalk) else None)
    ever = np.zeros((2, exp.shape[1]), dtype=bool)   # seen in each view so far (for the walks)
    shift = (ShiftCheck(rest_points)
             if cameras is not None and rest_points is not None and settings.shift_check else None)
    dots_seen = []                                   # each frame's dots per view: for the shift check only
    pending = (PendingAcquisitions(exp.shape[1], settings.acquire_pending)
               if cameras is not None and settings.acquire_pending else None)
    recheck = (IdentityCheck(rest_points, settings.identity_recheck, layout_covariance)
               if cameras is not None and rest_points is not None and settings.identity_recheck else None)
    motion_cov = layout_covariance if settings.motion_physics_prior else None
    motion = (MotionCheck(rest_points, covariance=motion_cov)
              if cameras is not None and rest_points is not None and settings.motion_check else None)
    for t, raw in enumerate(raw_frames):
        views = layout.split_views(np.asarray(raw))
        if t == 0:
            inits, bad, found = first_frame(views, exp, settings, cameras, rest_points, names,
                                            layout_covariance)
            n_dots = [len(d) for d in found]
            for v in range(2):
                ok = np.all(np.isfinite(exp[v]), axis=1)
                trackers.append(MarkerTracker(inits[v], settings.tracker, np.where(ok[:, None], exp[v], 0.0)))
                # What the tracker really starts with: twins and matches the views contradict are out.
                started = np.all(np.isfinite(trackers[v].init), axis=1)
                log.info("%s view: %d dots in the first frame, %d of %d markers matched%s", VIEWS[v],
                         n_dots[v], int(started.sum()), len(ok),
                         "" if started.all() else " (not: " + ", ".join(
                             str(i) if names is None else names[i] for i in np.flatnonzero(~started)) + ")")
        for tracker, img in zip(trackers, views, strict=True):
            tracker.step(img)
        if shift is not None:
            dots_seen.append(tuple(tr.dot_history[-1][0] for tr in trackers))
        if t == 0:
            for tracker in trackers:
                tracker._rejected[0] |= bad     # the first-frame matches the other view contradicted
        if cameras is not None and t > 0:
            if settings.epipolar_recovery:
                recover_along_epipolar(trackers, views, cameras, gap_limit.limit(),
                                       blobs=settings.epipolar_blobs,
                                       blob_share=settings.epipolar_blob_share)
            if settings.confirm_blobs and settings.tracker.blobs:
                confirm_blobs(trackers)      # after the recovery: a dot found on its epipolar line confirms
            if settings.one_view_pairing and rest_points is not None:
                fresh = np.stack([tr.acquired for tr in trackers])
                fresh |= False if pending is None else pending.since >= 0
                pair_one_view(trackers, views, cameras, rest_points, gap_limit.limit(), fresh, names=names)
            if pending is not None:
                forgot = pending.step(trackers, cameras, gap_limit.limit())
                ever &= ~forgot
            check_views(trackers, cameras, gap_limit, last3d, steps, since, names,
                        settings.identity_reference_age)
        if cameras is not None and settings.twin_model:
            resolve_twins(trackers, views, cameras, settings.tracker.dots.sigma / 1.7)
        changed = None
        if recheck is not None and t > 0:
            changed = recheck.step(trackers, views, cameras, gap_limit.limit(), last3d, steps, names, since)
        if motion is not None and t > 0:
            motion.step(trackers, views, cameras, last3d, since, names, changed)
        if walks is not None:
            seen = np.stack([(tr._out[-1][1] != LOST) & ~tr.twins for tr in trackers])
            if t > 0:
                walks.step(trackers, cameras, (seen & ~ever) if settings.backfill else np.zeros_like(seen),
                           gap_limit.limit(), steps, settings.rewalk, names)
            ever |= seen
        if progress is not None:
            progress(t)
    if not trackers:
        raise ValueError("track_raw_frames got no frames")
    tracks = trackers[0].tracks(), trackers[1].tracks()
    if shift is not None:
        tracks = shift.take_back(tracks, dots_seen, cameras, names)[0]
    if cameras is not None and rest_points is not None and settings.out_of_place_k is not None:
        tracks = take_back_out_of_place(tracks, cameras, rest_points, layout_covariance,
                                        k=settings.out_of_place_k, names=names)[0]
    return tracks


def triangulate_tracks(views: tuple[PinholeCamera, PinholeCamera], tracks: tuple[Tracks, Tracks],
                       max_ray_gap: float = np.inf) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ray-midpoint triangulation of tracked markers (thesis §3).

    Parameters
    ----------
    views : (virtual, real) PinholeCamera
    tracks : (virtual, real) Tracks
    max_ray_gap : float
        Pairs whose rays pass farther apart than this (mm) are rejected.

    Returns
    -------
    points : (F, P, 3) float
        World points, NaN where not visible.
    gap : (F, P) float
        Closest distance between the rays, mm (NaN where a view lost the marker).
    visible : (F, P) bool
        Seen in both views with rays closer than ``max_ray_gap``.
    """
    tv, tr = tracks
    if tv.uv.shape != tr.uv.shape:
        raise ValueError(f"the views' tracks differ in shape: virtual {tv.uv.shape}, real {tr.uv.shape}")
    both = tv.visible & tr.visible
    points = np.full(tv.uv.shape[:2] + (3,), np.nan)
    gap = np.full(tv.uv.shape[:2], np.nan)
    if both.any():
        p, g = triangulate(views[1], tr.uv[both], views[0], tv.uv[both])
        points[both], gap[both] = p, g
    return _within(points, gap, max_ray_gap)


def _within(points: np.ndarray, gap: np.ndarray, max_ray_gap: float
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Keep the pairs whose rays pass within ``max_ray_gap`` (NaN gap: a view lost the marker)."""
    visible = gap <= max_ray_gap
    rejected = int((np.isfinite(gap) & ~visible).sum())
    if rejected:
        log.warning("%d marker sighting(s) rejected: their rays pass more than %.2f mm apart", rejected,
                    max_ray_gap)
    return np.where(visible[..., None], points, np.nan), gap, visible


def triangulate_within_limit(views: tuple[PinholeCamera, PinholeCamera], tracks: tuple[Tracks, Tracks],
                             settings) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """:func:`triangulate_tracks` with the limit measured from this sequence's own ray gaps
    (``settings.ray_gap_limit``, :mod:`lipgen.recon.raygap`), triangulating once.

    Returns
    -------
    points, gap, visible
        As :func:`triangulate_tracks`.
    max_gap : float
        The limit, mm.
    """
    points, gap, _ = triangulate_tracks(views, tracks)
    limit = settings.ray_gap_limit(views)
    limit.add(gap[gap <= settings.max_ray_gap])
    max_gap = limit.limit()
    return (*_within(points, gap, max_gap), max_gap)


def reach_fields(physics, goals, visible, marker_nodes, min_visible: int = 4) -> np.ndarray:
    """The least-strain displacement field reaching each frame's visible marker goals (eq 4.3).

    Parameters
    ----------
    physics : lipgen.Physics
        The reconstruction model.
    goals : (F, P, 3) float
        Marker displacement goals in the model frame, mm (NaN where not visible).
    visible : (F, P) bool
    marker_nodes : (P,) int
        The model node of each marker.
    min_visible : int
        Frames with fewer visible markers get a NaN field.

    Returns
    -------
    (F, n, 3) float
        Displacement fields, mm.
    """
    from lipgen.fem import dofs

    G = as_float_array(goals, "goals", (None, len(marker_nodes), 3), finite=False)
    vis = np.asarray(visible, dtype=bool)
    if vis.shape != G.shape[:2]:
        raise ValueError(f"visible must have shape {G.shape[:2]}, got {vis.shape}")
    vis = vis & np.all(np.isfinite(G), axis=2)
    nodes = np.asarray(marker_nodes, dtype=np.int64)
    U = np.full((len(G), physics.mesh.n_nodes, 3), np.nan)
    patterns, which = np.unique(vis, axis=0, return_inverse=True)
    for k, pattern in enumerate(patterns):
        frames = np.flatnonzero(which.ravel() == k)
        if pattern.sum() < min_visible:
            log.warning("%d frame(s) see only %d markers (< %d): no field reconstructed", len(frames),
                        int(pattern.sum()), min_visible)
            continue
        values = G[frames][:, pattern].reshape(len(frames), -1)
        U[frames], _ = physics.reach(dofs(nodes[pattern]), values)
    return U
