"""The reconstruction of a dataset folder: ``lipgen reconstruct DATASET --out recon.npz``.

calibrate (chessboard frames) -> lab frame -> track both views -> triangulate -> normalise
(by default the least-force head pose about the nose, :mod:`lipgen.recon.headpose`; the thesis's §3
lip-plane frame with ``normalisation="thesis"``) -> ``Physics.reach`` per frame on the model mesh
(§4.1). Nothing here reads the
ground truth: the truth files are used only by :mod:`lipgen.evaluate` to score the result.

The lab frame. The calibration gives cameras in the frame of the chessboard in the first
calibration image, which may be tilted anyhow. The lab frame is set up from the rig itself, as a
person would place the subject: its origin is where the two views' central rays pass closest
(the rig aims there), y is the camera's up, and z points from the face toward the cameras (the
bisector of the directions to the real and the virtual camera). The model's rest markers,
placed there, are projected to get the layout that initialises tracking; the 2-D alignment of
:func:`lipgen.recon.pointreg.register_points` absorbs where the subject really sits.
"""

from __future__ import annotations

import json
import logging
import os
import time
from dataclasses import asdict, dataclass, replace

import numpy as np

from lipgen._io import load_npz, save_npz
from lipgen._threads import blas_threads
from lipgen.errors import DatasetError, TopologyMismatchError
from lipgen.mesh.lipmesh import LipMesh
from lipgen.recon.account import sighting_account
from lipgen.recon.anchor import track_from_anchor
from lipgen.recon.calibcache import calibrated
from lipgen.recon.calibrate import RigCalibration
from lipgen.recon.crosscheck import arbitrate, cross_check, reversed_run, runs_agree
from lipgen.recon.extend import extend_tracks
from lipgen.recon.gapfill import fill_short_gaps
from lipgen.recon.modelmesh import model_mesh
from lipgen.recon.normalize import METHODS, lip_subsets, normalize_markers
from lipgen.recon.nose import NoseNeverSeen, settle_nose
from lipgen.recon.shareddot import take_back_shared
from lipgen.recon.split import training_candidates
from lipgen.recon.splitruns import take_back_disagreeing
from lipgen.recon.steps import (
    ReconstructSettings,
    expected_projections,
    reach_fields,
    track_raw_frames,
    triangulate_tracks,
    triangulate_within_limit,
)
from lipgen.rig.camera import VIEWS

__all__ = ["Reconstruction", "reconstruct_dataset", "lab_frame", "model_mesh", "dot_sigma_px"]

log = logging.getLogger(__name__)

_KIND, _SCHEMA = "lipgen.Reconstruction", 1


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """What ``lipgen reconstruct`` produces (all lengths mm, model frame unless stated).

    Attributes
    ----------
    fields : (F, n, 3) float
        Least-strain displacement field of each frame on the model mesh (NaN rows: too few
        markers seen). Markers the normalisation left out as outliers
        (``info["normalisation"]["outliers"]``, [frame, marker] pairs) are not its goals.
    markers : (F, P, 3) float
        Normalised markers (NaN where not visible).
    visible : (F, P) bool
        Marker seen in both views with consistent rays.
    lab_points : (F, P + 1, 3) float
        Triangulated markers then the nose, lab frame.
    ray_gap : (F, P + 1) float
        Distance between the two rays of each triangulation.
    uv, status, score : (2, F, P + 1, 2), (2, F, P + 1), (2, F, P + 1)
        Tracks per view (:data:`lipgen.rig.camera.VIEWS` order).
    frame_index : (F,) int
    lab_to_board : (4, 4) float
        Lab point p -> calibration-board point ``R p + t`` (for scoring against the world).
    similarity : (4, 4) float
        The one similarity (reference frame -> model), as ``[[s R, t], [0, 1]]``.
    rotations : (F, 3, 3) float
        Per-frame rotations applied before it (the lip frames for the thesis method).
    info : dict
        Mesh source and topology, marker names, calibration, settings, timings, dataset path.
    """

    fields: np.ndarray
    markers: np.ndarray
    visible: np.ndarray
    lab_points: np.ndarray
    ray_gap: np.ndarray
    uv: np.ndarray
    status: np.ndarray
    score: np.ndarray
    frame_index: np.ndarray
    lab_to_board: np.ndarray
    similarity: np.ndarray
    rotations: np.ndarray
    info: dict

    @property
    def calibration(self) -> RigCalibration:
        return RigCalibration.from_dict(self.info["calibration"])

    @property
    def lab_calibration(self) -> RigCalibration:
        """The calibrated rig in the lab frame (what the triangulation used)."""
        T = np.linalg.inv(self.lab_to_board)
        return self.calibration.in_frame(T[:3, :3], T[:3, 3])

    def save(self, path: str | os.PathLike) -> None:
        """Write the reconstruction to an ``.npz`` file (atomic; schema-versioned)."""
        arrays = {k: getattr(self, k) for k in ("fields", "markers", "visible", "lab_points", "ray_gap", "uv",
                                                 "status", "score", "frame_index", "lab_to_board",
                                                 "similarity", "rotations")}
        arrays["info"] = np.array(json.dumps(_paths_relative_to(self.info, path), sort_keys=True))
        save_npz(path, _KIND, _SCHEMA, arrays)

    @classmethod
    def load(cls, path: str | os.PathLike) -> Reconstruction:
        """Read a reconstruction written by :meth:`save`, checking its kind and schema."""
        names = ("fields", "markers", "visible", "lab_points", "ray_gap", "uv", "status", "score",
                 "frame_index", "lab_to_board", "similarity", "rotations", "info")
        d = load_npz(path, _KIND, _SCHEMA, required=names)
        from lipgen.recon.reconfile import check_recon_arrays

        check_recon_arrays(path, d)
        info = _paths_resolved_from(json.loads(str(d.pop("info"))), path)
        return cls(**{k: d[k] for k in names if k != "info"}, info=info)


_PATH_KEYS = ("dataset", "mesh_source", "rest_from")
"""Paths in ``Reconstruction.info``: absolute in memory, relative to the file on disk (a file
names no folder of the machine it was made on, and still finds its dataset and mesh when the
two move together)."""


def _is_file_source(value) -> bool:
    return isinstance(value, str) and bool(value) and not value.startswith("lip_mesh(")


def _paths_relative_to(info: dict, path) -> dict:
    base = os.path.dirname(os.path.abspath(path))
    out = dict(info)
    for key in _PATH_KEYS:
        if _is_file_source(out.get(key)):
            try:
                out[key] = os.path.relpath(os.path.abspath(out[key]), base)
            except ValueError:  # another drive (Windows): keep only the name
                out[key] = os.path.basename(out[key])
    return out


def _paths_resolved_from(info: dict, path) -> dict:
    base = os.path.dirname(os.path.abspath(path))
    out = dict(info)
    for key in _PATH_KEYS:
        if _is_file_source(out.get(key)) and not os.path.isabs(out[key]):
            out[key] = os.path.normpath(os.path.join(base, out[key]))
    return out


def lab_frame(cal: RigCalibration) -> np.ndarray:
    """(4, 4) lab -> board transform set up from the calibrated rig (see the module docstring)."""
    rig = cal.rig
    origins, dirs = [], []
    for cam in rig.views:
        o, d = cam.rays(np.array([(cam.width - 1) / 2, (cam.height - 1) / 2]))
        origins.append(o)
        dirs.append(d)
    from lipgen.rig.pinhole import triangulate_rays

    aim, _ = triangulate_rays(origins[1], dirs[1], origins[0], dirs[0])
    up = -rig.camera.R[1]
    toward = sum((c.center - aim) / np.linalg.norm(c.center - aim) for c in rig.views)
    z = toward - (toward @ up) * up
    z /= np.linalg.norm(z)
    y = up - (up @ z) * z
    y /= np.linalg.norm(y)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([np.cross(y, z), y, z])
    T[:3, 3] = aim
    return T


def dot_sigma_px(cal: RigCalibration, lab_to_board: np.ndarray, dot_diameter: float) -> float:
    """Detector scale for ink dots of ``dot_diameter`` mm at the lab origin, pixels.

    A disc of radius r pixels looks like a Gaussian of sigma ~ r / 2, but on rendered frames the
    detector works best a good deal wider (fewer false dots on shading and the mouth corners,
    no loss of accuracy): 0.85 r in the view that sees the dots smallest, and never below 1.2 px.
    """
    origin = lab_to_board[:3, 3]
    px_per_mm = min(c.K[0, 0] / (c.R @ origin + c.t)[2] for c in cal.views)
    return float(np.clip(0.85 * dot_diameter / 2 * px_per_mm, 1.2, 6.0))


def _check_marks(ds, mesh: LipMesh) -> None:
    names = [str(n) for n in ds.manifest["marks"][:-1]]
    if list(mesh.marker_names) != names:
        raise TopologyMismatchError(
            f"the dataset's markers {names} are not the model mesh's {list(mesh.marker_names)}: the dataset "
            f"was made from a different mesh (topology {ds.manifest['mesh'].get('topology_id')}) than the "
            f"model {mesh.name!r}; reconstruct it with a model mesh that has the same markers (--mesh)")


def reconstruct_dataset(path, mesh_source: str = "lip_mesh(0)", settings: ReconstructSettings | None = None,
                        progress: bool = False, normalisation: str = "least-force",
                        test_frames: int | None = None, reference_frames=None, rest: str | None = None,
                        rest_from=None) -> Reconstruction:
    """Run the whole reconstruction on a dataset folder (see the module docstring).

    ``normalisation`` is one of :data:`lipgen.recon.normalize.METHODS`. The normalisation's
    reference frame is the most neutral-looking of the training frames: all but the last
    ``test_frames`` (default :func:`lipgen.recon.split.default_test_frames`, as ``lipgen train``
    holds out), or only the ``reference_frames`` named.

    ``rest`` (``"model"``, ``"recording"`` or ``"auto"``; None:
    :data:`lipgen.recon.restsource.DEFAULT_REST`, the model's) and ``rest_from`` (the path of
    another reconstruction) say where the displacements are measured from
    (:mod:`lipgen.recon.restsource`). ``"auto"`` takes the model's rest, and says so, when the
    training frames are too few for a rest of their own (``"recording"`` refuses) or when its rest
    frames are one stretch rather than pauses (``"recording"`` takes it, with a warning).

    ``settings`` (default: :class:`~lipgen.recon.settings.ReconstructSettings`): the tracker's dot
    detector is fitted to the rig's dot size (:func:`dot_sigma_px`) unless ``settings.tracker.dots.sigma``
    was changed from its default.
    """
    from lipgen.dataset.layout import Dataset
    from lipgen.fem import Physics
    from lipgen.recon.rest import MIN_REST_FRAMES
    from lipgen.recon.restsource import (
        MIN_PAUSES,
        check_rest_from,
        check_rest_options,
        measured_from_rest,
        rest_frames,
    )

    if normalisation not in METHODS:
        raise ValueError(f"unknown normalisation {normalisation!r}; choose one of {METHODS}")
    t0, c0 = time.perf_counter(), time.process_time()  # wall and this process's CPU
    ds = Dataset(path)
    candidates = training_candidates(len(ds), test_frames, reference_frames)
    missing = ds.missing(truth=False)     # the truth is never read here: a recording has none
    if missing:
        raise DatasetError(f"{path}: {len(missing)} of {len(ds)} frames are missing (e.g. frame "
                           f"{missing[0]}); finish the dataset with lipgen generate --resume before "
                           "reconstructing")
    calib = ds.manifest["calibration"]["frames"]
    absent = [f["raw"] for f in calib if not (ds.path / f["raw"]).is_file()]
    if len(calib) == 0 or absent:
        what = "the manifest lists none" if not calib else ", ".join(absent) + " missing"
        raise DatasetError(f"{path}: no calibration images ({what}); the rig is calibrated from chessboard "
                           "photos: build the folder with lipgen recording init VIDEO --calib DIR")
    mesh = model_mesh(mesh_source)
    _check_marks(ds, mesh)
    rest_kind = check_rest_options(rest, rest_from)
    auto = rest_kind == "auto"  # the recording's rest from 2 pauses, else the model's, saying why
    rest_kind = "recording" if auto else rest_kind
    lender = None if rest_from is None else check_rest_from(Reconstruction.load(rest_from), mesh, rest_from)
    frames_at_rest = (rest_frames(len(ds), test_frames, explicit=not auto)
                      if rest_kind == "recording" and lender is None else None)
    short = (f"{len(ds)} frames leave fewer than {MIN_REST_FRAMES} training frames for a rest of their own"
             if rest_kind == "recording" and lender is None and frames_at_rest is None else None)
    if short:
        log.warning("%s: measured from the model's rest", short)
    # once per process for the same images (a small bundle adjustment, on one BLAS thread)
    cal = calibrated([c.image for c in ds.calibration()], ds.rig, ds.calibration_boards())
    t_cal, c_cal = time.perf_counter(), time.process_time()
    T = lab_frame(cal)
    lab = cal.in_frame(T[:3, :3].T, -T[:3, :3].T @ T[:3, 3])
    from lipgen.recon.dots import DotSettings

    settings = ReconstructSettings() if settings is None else settings
    if settings.tracker.dots.sigma == DotSettings().sigma:
        # the detector's size fitted to this rig's dots unless the caller set it (its default sigma
        # is no rig's: default 1 fell from 96.5 to 93.2 % accepted); its other settings kept
        dots = replace(settings.tracker.dots, sigma=dot_sigma_px(cal, T, float(ds.settings.dot_diameter)))
        settings = replace(settings, tracker=replace(settings.tracker, dots=dots))
    marks_rest = np.vstack([mesh.vertices[mesh.markers], mesh.nose])
    expected = expected_projections(lab.views, marks_rest)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(ds) * (2 if settings.cross_check else 1), desc="tracking", unit="frame")
    names = [*mesh.marker_names, "nose"]
    physics = Physics(mesh)  # a large factorisation keeps its threads
    layout_cov = None
    if settings.physics_layout_prior:
        from lipgen.recon.layoutprior import physics_layout_covariance

        with blas_threads(1):  # the same bits whatever the thread count: it feeds threshold tests
            layout_cov = physics_layout_covariance(physics)

    def track(frames, progress):
        return track_raw_frames(frames, ds.rig, expected, settings, progress, cameras=lab.views, names=names,
                                rest_points=marks_rest, layout_covariance=layout_cov)

    with blas_threads(1):  # per-frame work of tiny BLAS calls (lipgen._threads)
        tracks, anchor = track_from_anchor(lambda i: ds[i].image, len(ds), track, settings.anchor_step,
                                           (lambda _: bar.update()) if bar else None)
        crossed, shared, sure = None, [], None
        if settings.cross_check:
            second, back = reversed_run(lambda i: ds[i].image, len(ds), track, settings.anchor_step,
                                        (lambda _: bar.update()) if bar else None)
            tol = settings.tracker.dots.separation   # the detector's: peaks nearer than this are one dot
            judge = None
            if settings.cross_check_arbitrate:
                def judge(a, b, disputed):
                    return arbitrate(a, b, disputed, lab.views, marks_rest, layout_cov,
                                     pairs=settings.cross_check_pairs, spread=settings.cross_check_spread,
                                     continuity=settings.cross_check_continuity)
            if settings.gap_fill_sure:
                sure = runs_agree(tracks, second, tol)
            tracks, crossed = cross_check(tracks, second, tol, settings.cross_check_fill, judge,
                                          settings.cross_check_keep)
            crossed = crossed | {"anchor": back}
        if settings.shared_dot_check:   # two markers on one dot: neither is trusted
            one_dot = settings.tracker.dots.separation / 2
            tracks, shared = take_back_shared(tracks, one_dot, names)
    if bar is not None:
        bar.close()
    t_track, c_track = time.perf_counter(), time.process_time()
    # The views disagree beyond a limit measured from this sequence's own ray gaps (recon.raygap).
    points, gap, vis, max_gap = triangulate_within_limit(lab.views, tracks, settings)

    def views_at(f):   # frame f's (virtual, real) images, for the steps that look again
        return ds.rig.split_views(np.asarray(ds[f].image))

    split = None
    if settings.split_runs is not None:
        judged = np.ones(vis.shape[1], dtype=bool)
        judged[len(mesh.markers):] = False   # the nose has no near neighbours to move with
        with blas_threads(1):
            tracks, split = take_back_disagreeing(tracks, vis, expected, settings.split_runs, judged,
                                                  mesh.marker_names, settings.split_runs_ratio,
                                                  settings.split_runs_spread)
        points, gap, vis = triangulate_tracks(lab.views, tracks, max_gap)
    gaps = None
    if settings.gap_fill:
        barred = np.zeros(vis.shape, dtype=bool)
        for span in shared:   # the shared-dot check's: neither marker is trusted there
            barred[slice(*span["frames"]), list(span["markers"])] = True
        if settings.gap_fill_sure and sure is None:   # no second run: nothing is sure
            sure = np.zeros(vis.shape, dtype=bool)
        with blas_threads(1):
            tracks, gaps = fill_short_gaps(tracks, views_at, lab.views, vis, settings.tracker.dots,
                                           settings.tracker.floor_min, max_gap, settings.gap_fill,
                                           sure=sure, barred=barred)
        points, gap, vis = triangulate_tracks(lab.views, tracks, max_gap)
    walks = None
    if settings.walk_on:
        start = vis.copy()
        start[:, len(mesh.markers)] = False   # the nose has no near neighbours: settle_nose looks for it
        with blas_threads(1):
            tracks, walks = extend_tracks(tracks, views_at, lab.views, vis, expected, settings.tracker.dots,
                                          settings.tracker.floor_min, max_gap, settings.tracker.gate,
                                          start=start, min_run=settings.walk_frames)
        points, gap, vis = triangulate_tracks(lab.views, tracks, max_gap)
    P = len(mesh.markers)
    upper, lower = lip_subsets(mesh.marker_names)
    try:
        with blas_threads(1):
            tracks, points, gap, vis, nose_record = settle_nose(
                views_at, tracks, points, gap, vis, lab.views,
                marks_rest, max_gap, settings.tracker.dots, settings.tracker.floor_min, settings.nose_search)
    except NoseNeverSeen as exc:
        raise DatasetError(f"{path}: the nose mark was never seen in both views, and {exc}; cannot normalise"
                           ) from None
    nose_seen = vis[:, P]
    if nose_seen.any() and not nose_seen.all():
        # Where the nose is lost, interpolate it in time (where never seen, settle_nose stood in for it).
        good = np.flatnonzero(nose_seen)
        log.warning("nose lost in %d frame(s): interpolated", int((~nose_seen).sum()))
        for a in range(3):
            points[~nose_seen, P, a] = np.interp(np.flatnonzero(~nose_seen), good, points[good, P, a])
    with blas_threads(1):  # per-frame poses and reaches: many small products and solves
        norm = normalize_markers(points[:, :P], points[:, P], upper, lower, mesh.vertices[mesh.markers],
                                 model_nose=mesh.nose, visible=vis[:, :P], reference_frame="auto",
                                 method=normalisation, physics=physics, reference_candidates=candidates)
        # Markers the normalisation found mis-measured (one marker carrying most of a frame's cost)
        # are not goals of the frame's field; they stay in `markers` and `visible` (the tracker's word).
        outliers = np.zeros((len(points), P), bool) if norm.outliers is None else norm.outliers
        fields = reach_fields(physics, norm.markers - mesh.vertices[mesh.markers], vis[:, :P] & ~outliers,
                              mesh.markers, settings.min_visible)
    account = sighting_account(tracks, vis, gap, max_gap, outliers, names, expected,
                               [(c.width, c.height) for c in lab.views], settings.tracker.twins)
    if account["never_tracked"]:
        log.warning("never tracked in a view (why: info['sightings']['never_tracked']): %s",
                    "; ".join(f"{n['mark']} ({n['view']})" for n in account["never_tracked"]))
    if account["missing"]:
        log.warning("no accepted sighting at all of %s: the fields reach the other markers only",
                    ", ".join(account["missing"]))
    t_end = time.perf_counter()
    S = np.eye(4)
    S[:3, :3] = norm.similarity.scale * norm.similarity.rotation
    S[:3, 3] = norm.similarity.translation
    info = {
        "dataset": str(os.path.abspath(path)),
        "mesh_source": mesh_source if not _is_file_source(mesh_source) else os.path.abspath(mesh_source),
        "topology_id": mesh.topology_id,
        "n_nodes": mesh.n_nodes, "marker_names": list(mesh.marker_names), "views": list(VIEWS),
        "calibration": cal.to_dict(), "settings": json.loads(json.dumps(asdict(settings))),
        "ray_gap_limit_mm": max_gap, "tracking_anchor": anchor, "cross_check": crossed, "nose": nose_record,
        "shared_dots": shared, "gap_fill": gaps, "walk_on": walks, "split_runs": split,
        "normalisation": {"method": norm.method, "fit_rms_mm": norm.fit_rms, "scale": norm.similarity.scale,
                          "reference_frame": norm.reference_frame,
                          "reference_from": (f"frames 0-{int(candidates.max())} (training frames)"
                                             if reference_frames is None else candidates.tolist()),
                          "borrowed_frames": int(norm.borrowed.sum()),
                          "outliers": np.argwhere(outliers).tolist(),
                          **({"plane_angle_deg_median": float(np.degrees(np.nanmedian(norm.plane_angle)))}
                             if norm.method == "thesis" else {})},
        "sightings": account,
        "seconds": {"calibration": t_cal - t0, "tracking": t_track - t_cal, "rest": t_end - t_track},
        "cpu_seconds": {"calibration": c_cal - c0, "tracking": c_track - c_cal},
    }
    recon = Reconstruction(
        fields=fields, markers=norm.markers, visible=vis[:, :P], lab_points=points, ray_gap=gap,
        uv=np.stack([t.uv for t in tracks]), status=np.stack([t.status for t in tracks]),
        score=np.stack([t.score for t in tracks]), frame_index=np.arange(len(ds)), lab_to_board=T,
        similarity=S, rotations=norm.rotations, info=info)
    recon = measured_from_rest(recon, physics, "model" if short else rest_kind, frames_at_rest, lender,
                               rest_from, why=short, min_pauses=MIN_PAUSES if auto else 0)
    recon.info["seconds"]["rest"] = time.perf_counter() - t_track
    recon.info["cpu_seconds"]["rest"] = time.process_time() - c_track
    return recon
