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
from dataclasses import dataclass, field

import numpy as np

from lipgen._validate import as_float_array
from lipgen.recon.backfill import WalkQueue
from lipgen.recon.dots import detect_dots
from lipgen.recon.epipolar import recover_along_epipolar
from lipgen.recon.firstframe import match_first_frame
from lipgen.recon.grow import check_first_frame
from lipgen.recon.jumps import StepLimit
from lipgen.recon.motioncheck import MotionCheck
from lipgen.recon.oneview import pair_one_view
from lipgen.recon.pending import PendingAcquisitions
from lipgen.recon.raygap import RayGapLimit, px_per_mm
from lipgen.recon.recheck import IdentityCheck
from lipgen.recon.stereo_init import layout_dots
from lipgen.recon.track import LOST, MarkerTracker, TrackerSettings, Tracks
from lipgen.recon.twins import resolve_twins
from lipgen.recon.viewcheck import check_views
from lipgen.rig.camera import VIEWS, MirrorRig
from lipgen.rig.pinhole import PinholeCamera, triangulate

__all__ = ["ReconstructSettings", "track_raw_frames", "triangulate_tracks", "reach_fields",
           "expected_projections"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ReconstructSettings:
    """Settings of the reconstruction.

    Attributes
    ----------
    tracker : TrackerSettings
        Dot look and tracking parameters.
    init_gate : float
        Largest distance (px) between a first-frame dot and its marker's expected position
        after the 2-D alignment.
    max_ray_gap : float
        Largest distance (mm) between a marker's two rays; beyond it the pair is a mis-track
        and the marker is treated as not seen in that frame.
    min_visible : int
        Fewest visible markers for a frame's field to be reconstructed (else its field is NaN).
    twin_model : bool
        Find markers whose dots merge in one view (twins) with a model of both dots on their
        epipolar lines from the other view (:mod:`lipgen.recon.twins`).
    ray_gap_k : float or None
        The views disagree when the rays pass farther apart than ``ray_gap_k`` times the median
        gap of the sequence's agreeing sightings (:class:`lipgen.recon.raygap.RayGapLimit`),
        within [``min_ray_gap_px``, ``max_ray_gap``]; None: ``max_ray_gap`` alone.
    min_ray_gap_px : float
        Least ray-gap limit, in pixels at the lab origin (converted to mm by the calibrated views).
    first_frame_lures : bool
        Drop first-frame matches on dots that no dot of the other view places near the marker
        layout in 3-D (:func:`lipgen.recon.stereo_init.layout_dots`). Off: measured before
        ``first_frame_dark`` and ``first_frame_layout`` existed, it cut the validation sets'
        accepted sightings over 3 px from 141 to 99 but accepted fewer (66.7 -> 63.9 %) and was
        worse on hard seed 9 (16 -> 55 over 3 px).
    robust_first_frame : bool
        Match the first frame with the trimmed registration (``robust`` of
        :func:`lipgen.recon.pointreg.match_to_expected`): outlying matches are left out of the
        similarity fit and of the deformation, and the markers left unmatched are acquired on
        later frames. Off: measured before ``first_frame_dark`` and ``first_frame_layout``
        existed, it was better on the validation sets in total (57.9 -> 66.7 % accepted, 163 ->
        141 over 3 px) but the recording tutorial's 20-frame H.264 clip then never acquired
        ``lower_mid`` (exit status 3), and hard test seed 12 collapsed (29.7 -> 3.1 %).
    step_k : float or None
        A sighting whose 3-D point moved farther from the marker's last accepted point than
        ``step_k`` times the 90th percentile of that marker's accepted steps (per frame, at least
        ``min_step``) is a jump along the epipolar line and is taken back in both views
        (:class:`lipgen.recon.jumps.StepLimit`); None: no step check.
    min_step : float
        Least step limit, mm per frame.
    epipolar_recovery : bool
        Look for a marker lost in one view on the epipolar line of the other view's sighting,
        where a faint dot (under the detector's contrast floor: the defocused mirror view of
        ``hard``) may be taken (:func:`lipgen.recon.epipolar.recover_along_epipolar`); it then
        passes the same view checks as any re-acquired sighting.
    first_frame_layout : bool
        Check the first frame's matches of both views jointly in 3-D against the model's marker
        layout (:func:`lipgen.recon.firstframe.check_layout`): a match whose triangulated point is
        out of place (a lure along the epipolar line, which the ray gap cannot see) takes the pair
        of free dots nearest where the other markers put it, or its wrong view is left unmatched.
    first_frame_grow : bool
        With ``first_frame_layout``: grow the first frame's matches from the markers matched in
        both views, in 3-D along the epipolar lines (:func:`lipgen.recon.grow.grow_first_frame`),
        then check the layout again.
    first_frame_dark : float or None
        Match each view's first frame on the dots at least this fraction as dark as the median
        of the markers' dots (:func:`lipgen.recon.firstframe.match_first_frame`); None: all dots.
        On ``default`` the lures near the lips are skin blobs at 0.29-0.36 of the markers'
        median darkness, the faintest marker dots at 0.45-0.62 (validation seeds 7, 8).
    backfill : bool
        With the calibrated cameras, a marker first seen in a view after the first frame is
        tracked back from there to the frames before it, each sighting confirmed by the other view
        (:func:`lipgen.recon.backfill.backfill`). With ``identity_recheck``, ``rewalk`` and
        ``walk_frames`` (measured together; calibrate, track, triangulate, scored against the
        truth; accepted share, accepted sightings over 3 px in both views; before -> after): the
        demo's 150-frame ``easy`` clip 98.9 -> 99.6 %; validation ``default`` seeds 7 / 8 / 9
        89.7 / 94.6 / 92.5 -> 92.1 / 97.4 / 92.8 %, over 3 px 0 / 8 / 0 -> 0 / 0 / 0; noise 32
        seeds 7-10 +0 to +1.6 points, the same 3 over 3 px; ``hard`` seeds 7-10 23.2 / 80.3 /
        77.2 / 53.8 -> 23.9 / 82.6 / 83.1 / 62.2 %, over 3 px 60 / 1 / 26 / 35 -> 67 / 1 / 26 / 37;
        easy seed 7 unchanged (99.9 %). Test seeds ``default`` 11 / 12 / 13 (once, at the end):
        93.5 / 93.3 / 98.4 -> 97.3 / 93.4 / 99.4 %, over 3 px 30 / 0 / 0 -> 0 / 0 / 0.
    identity_recheck : int or None
        With the calibrated cameras and the markers at rest, the first frame's 3-D layout check
        is run on every later frame too; a marker it gives a new dot this many frames in a row is
        re-tracked from there, forward and backward (:class:`lipgen.recon.recheck.IdentityCheck`).
        None: off. On 8-frame H.264 clips (640x480, crf 12) of seeds 5-10, the RMS difference
        from the PNG frames' tracks over sightings both accept: seed 5 1.42 -> 0.17 px (a lure
        9 px along the epipolar line, matched with the mouth open, re-identified at frame 3), the
        others 0.15-0.18 px as before.
    rewalk : bool
        With the calibrated cameras, a marker found again (after a loss, or from the motion
        prediction) in both views is walked back until the history agrees: frames it was lost in
        are filled, and earlier sightings on another dot replaced
        (:func:`lipgen.recon.backfill.rewalk`).
    walk_frames : int
        A walk back (``backfill``, ``rewalk``) is made once the marker has been seen in both
        views this many frames in a row from where the walk starts
        (:class:`lipgen.recon.backfill.WalkQueue`): a wrong pair taken back within a frame or two
        is not carried back.
    acquire_pending : int or None
        With the calibrated cameras, an acquisition the other view does not see yet is kept in
        its view for up to this many frames until the other view confirms it (rays that meet) or
        contradicts it (:class:`lipgen.recon.pending.PendingAcquisitions`); None: withdrawn at once.
        With ``first_frame_grow`` (main b0a1c18 -> both; accepted share of visible sightings,
        px RMS mirror / direct, accepted sightings over 3 px mirror / direct): hard 7 32.1 ->
        71.3 %, 2.77 / 10.76 -> 0.85 / 0.49 px, 9 / 52 -> 5 / 2; hard 8 82.3 % unchanged; hard 9
        78.8 -> 84.3 %, 1.45 / 1.73 -> 0.43 / 0.34 px, 13 / 14 -> 1 / 0; hard 10 62.2 -> 67.7 %,
        1.83 / 3.65 -> 2.14 / 1.93 px, 19 / 18 -> 18 / 17; default 7 / 8 / 9 92.1 / 97.4 / 92.8 ->
        97.9 / 98.1 / 98.4 %, none over 3 px before or after; easy 7 99.9 % and the demo's clip
        99.6 % unchanged. Grow alone: hard 7 74.7 % but 29 / 26 over 3 px, hard 10 64.2 %;
        pending alone: hard 7 / 9 / 10 31.5 / 78.1 / 58.3 %. Held out (once, after the freeze):
        default 11 / 12 / 13 97.3 / 93.4 / 99.4 -> 97.5 / 99.2 / 99.4 %, none over 3 px; hard 11
        / 12 / 13 (12 and 13 new) 71.2 / 69.3 / 79.1 -> 72.4 / 63.1 / 77.9 %, over 3 px 16 / 5 /
        8 -> 22 / 21 / 8: on ``hard`` no gain held out.
    motion_check : bool
        With the calibrated cameras and the markers at rest: every frame, each point is checked
        against the 3-D layout (behind the lips; a run out of place) and each step against the
        neighbours' steps; wrong sightings are taken back or swapped
        (:class:`lipgen.recon.motioncheck.MotionCheck`, which gives the figures). Validation
        ``hard`` 7-10 and 20-22: 199 -> 111 accepted sightings over 3 px.
    one_view_pairing : bool
        With the calibrated cameras and the markers at rest: a marker acquired in one view only
        takes the other view's dot where the 3-D layout puts it on its epipolar line
        (:func:`lipgen.recon.oneview.pair_one_view`; :mod:`lipgen.recon.oneview` gives the figures).
    physics_layout_prior : bool
        :func:`~lipgen.recon.pipeline.reconstruct_dataset` gives the 3-D layout checks of the first
        frame and of the identity re-check the model's physics prior
        (:mod:`lipgen.recon.layoutprior`). Off: validation ``hard`` 21 69 -> 25 accepted
        sightings over 3 px and ``hard`` 10 77.9 -> 78.6 % accepted, held out unchanged
        (``renders/examples/tracking/hard15k_physics_layout.md``); not yet adopted.
    """

    tracker: TrackerSettings = field(default_factory=TrackerSettings)
    init_gate: float = 6.0
    max_ray_gap: float = 2.0
    min_visible: int = 4
    twin_model: bool = True
    ray_gap_k: float | None = 8.0
    min_ray_gap_px: float = 1.0
    first_frame_lures: bool = False
    robust_first_frame: bool = False
    step_k: float | None = 4.0
    min_step: float = 1.0
    epipolar_recovery: bool = True
    first_frame_layout: bool = True
    first_frame_grow: bool = True
    first_frame_dark: float | None = 0.4
    backfill: bool = True
    identity_recheck: int | None = 3
    rewalk: bool = True
    walk_frames: int = 3
    acquire_pending: int | None = 10
    motion_check: bool = True
    one_view_pairing: bool = True
    physics_layout_prior: bool = False

    def ray_gap_limit(self, cameras) -> RayGapLimit:
        """A fresh :class:`~lipgen.recon.raygap.RayGapLimit` for the calibrated ``cameras``."""
        return RayGapLimit(self.max_ray_gap, self.ray_gap_k, self.min_ray_gap_px / px_per_mm(cameras))


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
    trackers: list[MarkerTracker] = []
    gap_limit = None if cameras is None else settings.ray_gap_limit(cameras)
    last3d = np.full((exp.shape[1], 3), np.nan)      # each marker's last accepted point (lab, mm)
    since = np.ones(exp.shape[1])                    # frames since then
    steps = None if settings.step_k is None else StepLimit(exp.shape[1], settings.step_k,
                                                           floor=settings.min_step)
    walks = (WalkQueue(exp.shape[1], settings.walk_frames)
             if cameras is not None and (settings.backfill or settings.rewalk) else None)
    ever = np.zeros((2, exp.shape[1]), dtype=bool)   # seen in each view so far (for the walks)
    pending = (PendingAcquisitions(exp.shape[1], settings.acquire_pending)
               if cameras is not None and settings.acquire_pending else None)
    recheck = (IdentityCheck(rest_points, settings.identity_recheck, layout_covariance)
               if cameras is not None and rest_points is not None and settings.identity_recheck else None)
    motion = (MotionCheck(rest_points)
              if cameras is not None and rest_points is not None and settings.motion_check else None)
    for t, raw in enumerate(raw_frames):
        views = layout.split_views(np.asarray(raw))
        if t == 0:
            inits, n_dots = [], []
            detected = [detect_dots(img, settings.tracker.dots) for img in views]
            found = [d[0] for d in detected]
            keep = [np.ones(len(d), dtype=bool) for d in found]
            if cameras is not None and rest_points is not None and settings.first_frame_lures:
                keep = layout_dots(found[0], found[1], cameras, rest_points)
            for v, dots in enumerate(found):
                ok = np.all(np.isfinite(exp[v]), axis=1)
                init = np.full(exp[v].shape, np.nan)
                match = np.full(len(ok), -1)
                match[ok] = match_first_frame(dots, detected[v][1], exp[v][ok], settings.init_gate,
                                              settings.robust_first_frame, settings.first_frame_dark)
                # Matched on all dots (a dot removed would leave its marker to a neighbour's), but
                # a match on a lure is dropped.
                lure = (match >= 0) & ~keep[v][np.maximum(match, 0)]
                if lure.any():
                    log.info("%s view, first frame: %d match(es) on dots no other-view dot places near "
                             "the layout dropped", VIEWS[v], int(lure.sum()))
                    match[lure] = -1
                init[match >= 0] = dots[match[match >= 0]]
                inits.append(init)
                n_dots.append(len(dots))
            bad = np.zeros(len(exp[0]), dtype=bool)
            if cameras is not None:
                inits, bad = check_first_frame(inits, found, cameras, settings.max_ray_gap,
                                               rest_points if settings.first_frame_layout else None,
                                               settings.first_frame_grow, names, layout_covariance)
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
        if t == 0:
            for tracker in trackers:
                tracker._rejected[0] |= bad     # the first-frame matches the other view contradicted
        if cameras is not None and t > 0:
            if settings.epipolar_recovery:
                recover_along_epipolar(trackers, views, cameras, gap_limit.limit())
            if settings.one_view_pairing and rest_points is not None:
                fresh = np.stack([tr.acquired for tr in trackers])
                fresh |= False if pending is None else pending.since >= 0
                pair_one_view(trackers, views, cameras, rest_points, gap_limit.limit(), fresh, names=names)
            if pending is not None:
                forgot = pending.step(trackers, cameras, gap_limit.limit())
                ever &= ~forgot
            check_views(trackers, cameras, gap_limit, last3d, steps, since, names)
        if cameras is not None and settings.twin_model:
            resolve_twins(trackers, views, cameras, settings.tracker.dots.sigma / 1.7)
        changed = None
        if recheck is not None and t > 0:
            changed = recheck.step(trackers, views, cameras, gap_limit.limit(), last3d, steps, names)
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
    return trackers[0].tracks(), trackers[1].tracks()


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
    visible = both & (gap <= max_ray_gap)
    rejected = int((both & ~visible).sum())
    if rejected:
        log.warning("%d marker sighting(s) rejected: their rays pass more than %.2f mm apart", rejected,
                    max_ray_gap)
    points[~visible] = np.nan
    return points, gap, visible


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
