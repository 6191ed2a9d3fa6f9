"""Scoring a reconstruction against the dataset's ground truth (thesis ch. 5 on synthetic data).

:func:`score` compares every stage with the truth files: the calibration with the true rig,
the tracks with the true projections, the triangulated markers with the true world marks, the
normalised markers with the true model-frame marks, and the LLSE reconstructions of the
held-out frames (the Table 5.1 analogue) both with the reach fields the thesis compared with and
with the true full surface. :mod:`lipgen.evaluate.report` turns the result into ``report.md`` and pictures.

The truth is read here only; nothing computed from it flows back into the reconstruction.
"""

from __future__ import annotations

import logging
import warnings
from collections import OrderedDict

import numpy as np

from lipgen.errors import DatasetError, TopologyMismatchError
from lipgen.evaluate.error_stats import error_figures, share
from lipgen.recon.calibrate import compare_to_truth
from lipgen.recon.normalize import lip_subsets, normalize_markers
from lipgen.recon.rest import measured_markers
from lipgen.recon.split import default_test_frames
from lipgen.rig.camera import VIEWS

__all__ = ["check_recon_mesh", "default_test_frames", "split_frames", "load_truth", "score", "table51",
           "accepted_sightings", "ROWS", "AXES", "sighting_errors", "tracking_table"]

log = logging.getLogger(__name__)

ROWS = ("xyz (8 points)", "yz (all points)", "xy (all points)")
"""The rows of the Table 5.1 analogue: which DOFs are observed (thesis Table 5.1)."""
AXES = {"xyz (8 points)": (8, "xyz"), "yz (all points)": (None, "yz"), "xy (all points)": (None, "xy")}
"""Per row: (number of marker points observed or None for all, the observed axes)."""
_ESTIMATOR_CACHE = 24  # estimators kept by table51 for frames that observe the same DOFs


def split_frames(fields: np.ndarray, test_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """(train, test) frame indices: the last ``test_frames`` are the test set; frames without a
    field (too few markers seen) are in neither."""
    F = len(fields)
    if not 1 <= test_frames < F:
        raise ValueError(f"test_frames must be in [1, {F - 1}] for {F} frames, got {test_frames}")
    ok = np.all(np.isfinite(fields.reshape(F, -1)), axis=1)
    idx = np.arange(F)
    return idx[ok & (idx < F - test_frames)], idx[ok & (idx >= F - test_frames)]


def load_truth(ds) -> dict:
    """Stack the per-frame truth of a :class:`lipgen.dataset.Dataset` (images are not kept)."""
    keys = ("marks_world", "marks_model", "uv", "visible", "vertices", "pose")
    out = {k: [] for k in keys}
    for i in range(len(ds)):
        truth = ds.truth(i)
        for k in keys:
            out[k].append(np.asarray(truth[k]))
    return {k: np.stack(v) for k, v in out.items()}


def _rms(err, axis=None):
    """RMS over the finite entries; NaN (no warning) where there are none, e.g. a never-seen marker."""
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # nanmean of an all-NaN slice
        return np.sqrt(np.nanmean(np.asarray(err) ** 2, axis=axis))


def accepted_sightings(recon) -> np.ndarray:
    """(F, P + 1) bool: marks seen in both views with agreeing rays and not left out by the
    normalisation as outliers (the nose: its rays agree)."""
    P = recon.visible.shape[1]
    out = np.zeros(recon.ray_gap.shape, dtype=bool)
    out[:, :P] = measured_markers(recon)
    max_gap = recon.info.get("ray_gap_limit_mm", recon.info.get("settings", {}).get("max_ray_gap", np.inf))
    with np.errstate(invalid="ignore"):
        out[:, P:] = recon.ray_gap[:, P:] <= max_gap
    return out


def sighting_errors(truth: dict, recon) -> dict:
    """Per view, every sighting's tracking error against the true projection and its class.

    ``truth`` is :func:`load_truth`'s (its ``uv`` (F, 2, P + 1, 2) and ``visible`` (F, 2, P + 1)).
    Returns ``{view: {"err": (F, P + 1) px (NaN where not tracked), "truly": visible per the truth,
    "got": found by the tracker (not lost), "accepted": :func:`accepted_sightings` (both views
    agree, not a pose outlier; the same in both views), "ok": truly visible and accepted}}``.
    """
    accepted = accepted_sightings(recon)
    out = {}
    for v, view in enumerate(VIEWS):
        truly = np.asarray(truth["visible"][:, v], dtype=bool)
        out[view] = {"err": np.linalg.norm(recon.uv[v] - truth["uv"][:, v], axis=-1), "truly": truly,
                     "got": recon.status[v] != 3, "ok": truly & accepted, "accepted": accepted}
    return out


def tracking_table(truth: dict, recon, errors: dict | None = None) -> dict:
    """The tracking figures of ``lipgen evaluate`` per view (its report's tracking table).

    Against the true projections, where the truth says the dot is visible. Only accepted
    sightings (both views agree, not a pose outlier) count as tracked; RMS, 95th percentile and
    > 3 px are over them (:func:`~lipgen.evaluate.error_stats.error_figures`). ``tracked_share`` is
    accepted / truly visible; it and ``wrong_over_3px_rate`` are NaN where their denominator is 0.
    ``errors``: :func:`sighting_errors` of the same truth and reconstruction, when the caller has them.
    """
    track = {}
    for view, e in (sighting_errors(truth, recon) if errors is None else errors).items():
        err, truly, got, ok, accepted = e["err"], e["truly"], e["got"], e["ok"], e["accepted"]
        n_ok, fig = int(ok.sum()), error_figures(err[ok])
        track[view] = {"rms_px": fig["rms_px"], "p95_px": fig["p95_px"],
                       "per_mark_rms_px": _rms(np.where(ok, err, np.nan), 0).tolist(),
                       "tracked_share": share(n_ok, int(truly.sum())), "accepted": n_ok,
                       "rejected": int((truly & got & ~accepted).sum()), "lost": int((truly & ~got).sum()),
                       "rms_all_sightings_px": float(_rms(err[truly & got])),
                       "false_sightings": int((got & ~truly).sum()),
                       "wrong_over_3px": fig["over_3px"], "wrong_over_3px_rate": share(fig["over_3px"], n_ok)}
    return track


def _true_fields(truth: dict, mesh, rest: np.ndarray | None = None) -> np.ndarray:
    """True displacement of the model's nodes (F, n, 3): the subject mesh nests the model's.

    ``rest`` (N, 3) is the subject's own rest mesh (its first n nodes are the anatomical points of
    the model's nodes; a subject with its own shape sits elsewhere at rest): the displacement is
    from there. Without it the subject is taken to have the model's rest shape."""
    V = truth["vertices"]
    n = mesh.n_nodes
    if V.shape[1] < n:
        raise TopologyMismatchError(f"the dataset's subject mesh has {V.shape[1]} nodes, fewer than the "
                                    f"model's {n}; it is not a refinement of the model mesh")
    return V[:, :n] - (mesh.vertices if rest is None else np.asarray(rest)[:n])


def table51(model, physics, recon, test: np.ndarray, true_fields: np.ndarray, n_modes: int = 10,
            combined: bool = True, noise=0.0, rest=None, robust: bool = False) -> dict:
    """Reconstruction error per DOF of the held-out frames (thesis Table 5.1), mm².

    For each row (which observed DOFs) and column (prior), the LLSE (eq 4.7) estimates every
    DOF of each test frame from that frame's visible markers; the error is the mean squared
    error per hidden DOF (:mod:`lipgen.evaluate.metric`, the definition ``lipgen experiment
    table51`` uses; each frame's hidden DOFs, averaged over the frames) against the frame's reach
    field (the thesis's reference) and against the true surface, and relative to the true test
    motion's own mean square on those DOFs (``vs_truth_relative``); ``vs_markers``: only at the
    hidden coordinates of the markers the frame measured (e.g. their z in the x-y row), against
    those measurements (``recon.markers − rest``), i.e. where a tracked recording has data (NaN
    where a row leaves no measured coordinate hidden). Columns: the first
    ``n_modes`` modes, the full sample covariance, the combined
    learned + physical model (§6.1), and the physics alone (``Physics.reach``, the baseline).

    ``combined`` is True (the combined model with the default prior and no noise), False (no
    such column) or a :class:`lipgen.modes.combined.CombinedModel`, e.g. one whose prior was chosen
    from the training fields by :meth:`~lipgen.modes.combined.CombinedModel.fit` (it then uses its
    estimated marker-noise variance). Its estimate is the scale mixture
    (:meth:`~lipgen.modes.combined.CombinedModel.mixture`: the residual variance weighed per frame).

    ``noise`` is the observation-noise variance (mm²) of the learned columns' LLSE: a scalar or
    ``(P, 3)`` per marker and axis (e.g. :func:`lipgen.modes.missing.second_difference_noise` of the
    training markers); 0 is the thesis's interpolating LLSE. A marker the model never learned from
    (``model.marker_coverage_`` 0: never measured in training) is not observed by the learned
    columns (its prior there is the physics' fill, not a measurement). ``rest`` (P, 3) is the rest
    the displacements are measured from (default the model's marker nodes). ``robust``: the learned
    columns weigh extra noise of unknown size per frame (:func:`lipgen.modes.mixture.noise_mixture`).
    """
    from lipgen.fem import dofs as node_dofs

    markers = np.asarray(physics.mesh.markers)
    P = len(markers)
    R = np.broadcast_to(np.asarray(noise, dtype=np.float64), (P, 3)) if np.ndim(noise) < 2 else \
        np.asarray(noise, dtype=np.float64)
    if R.shape != (P, 3) or not np.all(np.isfinite(R)) or (R < 0).any():
        raise ValueError(f"noise must be a variance >= 0 (mm²), scalar or ({P}, 3), got shape "
                         f"{np.shape(noise)}")
    coverage = getattr(model, "marker_coverage_", None)
    learned = np.ones(P, bool) if coverage is None else np.asarray(coverage) > 0
    learned_cols = (f"{n_modes} modes", "full covariance")
    columns = {learned_cols[0]: lambda d, r: model.llse(d, n_modes=n_modes, noise=r),
               learned_cols[1]: lambda d, r: model.llse(d, n_modes="full", noise=r)}
    if robust:
        from lipgen.modes.mixture import noise_mixture

        unit = float(np.mean(model.covariance("full").diag_blocks(markers).diagonal(axis1=1, axis2=2)))
        priors = {learned_cols[0]: model.covariance(n_modes), learned_cols[1]: model.covariance("full")}
        columns = {name: (lambda d, r, c=c: noise_mixture(c, d, model.mean_, r, unit))
                   for name, c in priors.items()}
    if combined is not False and combined is not None:
        try:
            from lipgen.modes.combined import CombinedModel

            comb = combined if isinstance(combined, CombinedModel) else CombinedModel(model, physics)
            columns["combined"] = lambda d, r: comb.mixture(d)
        except ImportError:
            log.warning("lipgen.modes.combined is not available: no combined-model column")
    from lipgen.evaluate.metric import hidden_dofs, per_dof_error, relative_error

    rest = physics.mesh.vertices[markers] if rest is None else np.asarray(rest, dtype=np.float64)
    if rest.shape != (P, 3):
        raise ValueError(f"rest must be the ({P}, 3) rest markers, got shape {rest.shape}")
    measured = measured_markers(recon)
    # Frames that see the same markers share their estimators: each is a pure function of the
    # observed DOFs and their noise (the combined column's scale mixture is one LLSE per grid
    # variance, so a build per frame dominated the scoring). The most recent few are kept.
    cache: OrderedDict = OrderedDict()

    def built(name, d, r):
        key = (name, d.tobytes(), None if r is None else r.tobytes())
        if key in cache:
            cache.move_to_end(key)
        else:
            cache[key] = columns[name](d, r)
            if len(cache) > _ESTIMATOR_CACHE:
                cache.popitem(last=False)
        return cache[key]

    out = {}
    for row in ROWS:
        count, axes = AXES[row]
        use = np.arange(len(markers) if count is None else count)
        ax = np.array(["xyz".index(a) for a in axes])
        cells = {name: {"vs_reach": [], "vs_truth": [], "vs_truth_relative": [], "vs_markers": []}
                 for name in (*columns, "physics (reach)")}
        for f in test:
            seen = use[recon.visible[f, use]]
            if len(seen) == 0:
                continue
            d = node_dofs(markers[seen], axes)
            hid = hidden_dofs(physics.free_dofs, d)
            y = (recon.markers[f, seen] - rest[seen])[:, ax].ravel()
            lseen = seen[learned[seen]]
            ld = node_dofs(markers[lseen], axes)
            ly = (recon.markers[f, lseen] - rest[lseen])[:, ax].ravel()
            lr = R[lseen][:, ax].ravel()
            ests = {name: (built(name, ld, lr).estimate(ly) if name in learned_cols else
                           built(name, d, None).estimate(y))
                    for name in columns if name not in learned_cols or len(lseen)}
            ests["physics (reach)"] = physics.reach(d, y)[0]
            # the hidden coordinates of the markers measured in this frame, against their measurement
            mk = np.flatnonzero(measured[f])
            md = node_dofs(markers[mk], "xyz")
            keep = np.isin(md, hid)
            mval = (recon.markers[f, mk] - rest[mk]).ravel()[keep]
            for name, est in ests.items():
                if keep.any():
                    cells[name]["vs_markers"].append(float(np.mean((est.ravel()[md[keep]] - mval) ** 2)))
                cells[name]["vs_reach"].append(per_dof_error(est[None], recon.fields[f][None], hid))
                cells[name]["vs_truth"].append(per_dof_error(est[None], true_fields[f][None], hid))
                cells[name]["vs_truth_relative"].append(relative_error(est[None], true_fields[f][None], hid))
        out[row] = {name: {k: float(np.mean(v)) if v else float("nan") for k, v in c.items()}
                    for name, c in cells.items()}
    return out


def _check_provenance(model, dataset_path, test) -> None:
    """Refuse test frames the model was trained on (its :attr:`provenance_`, from lipgen train)."""
    from lipgen.dataset.manifest import dataset_digest

    prov = getattr(model, "provenance_", None)
    if not prov or prov.get("dataset_id") is None or prov["dataset_id"] != dataset_digest(dataset_path):
        return
    seen = sorted(set(prov.get("frames", ())) & {int(f) for f in test})
    if seen:
        raise ValueError(f"the model was trained on frames {seen[:10]}{' ...' if len(seen) > 10 else ''} "
                         f"of this dataset ({len(seen)} of the {len(test)} test frames); test on frames it "
                         "has not seen: use the --test-frames given to lipgen train, or another dataset")


def check_recon_mesh(recon, mesh) -> None:
    """Refuse a reconstruction whose fields (F, n, 3) are not on its own mesh (an altered file):
    named here, not by a broadcasting error in the scoring."""
    if recon.fields.shape[1] != mesh.n_nodes:
        n = recon.fields.shape[1]
        raise ValueError(f"the reconstruction's fields {recon.fields.shape} have {n} nodes but its mesh "
                         f"{recon.info.get('mesh_source')} has {mesh.n_nodes}; the file was altered: "
                         "reconstruct again")


def score(ds, model, recon, test_frames: int | None = None, mesh=None) -> dict:
    """Every figure of the report, from a dataset, a trained model and its reconstruction."""
    from lipgen.fem import Physics
    from lipgen.recon.pipeline import model_mesh

    ds.require_truth("scoring a reconstruction (lipgen evaluate)")
    F = len(ds)
    if len(recon.fields) != F:
        raise DatasetError(f"the reconstruction has {len(recon.fields)} frames but the dataset {F}; it was "
                           "made from another dataset. Run lipgen reconstruct on this one")
    mesh = model_mesh(recon.info["mesh_source"]) if mesh is None else mesh
    if mesh.topology_id != recon.info["topology_id"]:
        raise TopologyMismatchError(
            f"the reconstruction was made on mesh topology {recon.info['topology_id']}, "
            f"not {mesh.topology_id}")
    model.check_mesh(mesh)
    check_recon_mesh(recon, mesh)
    truth = load_truth(ds)
    P = len(mesh.markers)
    out: dict = {"frames": F, "markers": P}
    # Calibration: the board in the reference calibration frame defines the calibrated world.
    cal = recon.calibration
    ref = ds.calibration()[cal.reference].truth
    A0, b0 = np.asarray(ref["A"]), np.asarray(ref["b"])
    out["calibration"] = {"rms_px": cal.rms, "vs_truth": compare_to_truth(cal.in_frame(A0, b0), ds.rig.views)}
    out["tracking"] = tracking_table(truth, recon)
    # Triangulation: lab -> board -> world.
    lab = recon.lab_points.reshape(-1, 3)
    board = lab @ recon.lab_to_board[:3, :3].T + recon.lab_to_board[:3, 3]
    world = (board @ A0.T + b0).reshape(recon.lab_points.shape)
    err3 = np.linalg.norm(world - truth["marks_world"], axis=-1)
    seen = np.concatenate([recon.visible, np.isfinite(recon.lab_points[:, P:, 0])], axis=1)
    out["triangulation"] = {"rms_mm": float(_rms(err3[seen])), "max_mm": float(np.nanmax(err3[seen])),
                            "per_mark_rms_mm": _rms(np.where(seen, err3, np.nan), 0).tolist(),
                            "visible_share": float(recon.visible.mean()),
                            "ray_gap_median_mm": float(np.nanmedian(recon.ray_gap))}
    # Normalisation: the pipeline's, the same method on the exact world marks, and the thesis's
    # method on them for comparison.
    marks_model = truth["marks_model"][:, :P]
    upper, lower = lip_subsets(mesh.marker_names)
    info = recon.info["normalisation"]
    method = info.get("method", "thesis")
    ref_used = info.get("reference_frame", 0)
    physics = Physics(mesh)

    def exact(meth, ref):
        n = normalize_markers(truth["marks_world"][:, :P], truth["marks_world"][:, P], upper, lower,
                              mesh.vertices[mesh.markers], model_nose=mesh.nose, reference_frame=ref,
                              method=meth, physics=physics)
        return float(_rms(np.linalg.norm(n.markers - marks_model, axis=-1)))

    thesis_exact = {("first frame" if ref == 0 else f"frame {ref}"): exact("thesis", ref)
                    for ref in (ref_used, 0)}
    out["normalisation"] = {
        "method": method,
        "rms_mm": float(_rms(np.linalg.norm(recon.markers - marks_model, axis=-1))),
        "exact_input_rms_mm": exact(method, ref_used) if method != "thesis" else thesis_exact[
            "first frame" if ref_used == 0 else f"frame {ref_used}"],
        "thesis_exact_input_rms_mm": thesis_exact,
        "reference_frame": ref_used, "fit_rms_mm": info["fit_rms_mm"],
        "outliers": len(info.get("outliers", [])),
        "scale": info["scale"], "metric_reference": info.get("metric_reference"),
        "head_rotation_deg_max": float(np.degrees(max(np.arccos(np.clip((np.trace(p[:3, :3]) - 1) / 2, -1, 1))
                                                      for p in truth["pose"])))}
    # Training data quality and the Table 5.1 analogue.
    true_fields = _true_fields(truth, mesh, ds.mesh.vertices)
    T = default_test_frames(F) if test_frames is None else int(test_frames)
    train, test = split_frames(recon.fields, T)
    _check_provenance(model, ds.path, test)
    if model.n_frames_ > len(train):
        raise ValueError(f"the model was trained on {model.n_frames_} frames but this reconstruction has "
                         f"only {len(train)} training frames before its last {T}; use the same "
                         "--test-frames as lipgen train")
    ok = np.all(np.isfinite(recon.fields.reshape(F, -1)), axis=1)
    from lipgen.recon.steps import reach_fields

    # The model's own floor: reach from the TRUE model-frame markers (no tracking, no normalisation).
    floor = reach_fields(physics, marks_model - ds.rest_marks()[:P], np.ones((F, P), bool),
                         mesh.markers)
    node_err = np.linalg.norm(recon.fields[ok] - true_fields[ok], axis=-1)
    out["fields"] = {"rms_mm_vs_truth": float(_rms(node_err)),
                     "true_rms_displacement_mm": float(_rms(np.linalg.norm(true_fields, axis=-1))),
                     "reach_from_true_markers_rms_mm": float(
                         _rms(np.linalg.norm(floor - true_fields, axis=-1))),
                     "frames_without_field": int((~ok).sum())}
    out["split"] = {"train": len(train), "test": test.tolist(),
                    "reference_frame_in_test": bool(ref_used in set(test.tolist()))}
    if out["split"]["reference_frame_in_test"]:
        log.warning("the normalisation's reference frame %d is a test frame: the held-out frames shaped "
                    "the training data; reconstruct with --test-frames %d", ref_used, T)
    from lipgen.evaluate.displacement import displacement_error
    from lipgen.recon.restsource import rest_frames_held_out, rest_line, rest_markers

    # Displacements from the rest the reconstruction measures from (lipgen reconstruct --rest).
    rest = rest_markers(recon, mesh)
    meas = measured_markers(recon)
    true_rest = ds.rest_marks()[:P]
    out["displacements"] = {"rest": rest_line(recon), "model_rest": (getattr(model, "provenance_", None)
                                                                      or {}).get("rest"),
                            **{k: displacement_error(recon.markers, meas, rest, marks_model, true_rest, fr)
                               for k, fr in (("all", None), ("train", train), ("test", test))}}
    held = rest_frames_held_out(recon, test)
    out["split"]["rest_frames_in_test"] = held
    if held:
        log.warning("the reconstruction's rest is the median of frames including test frames %s: the "
                    "held-out frames shaped the training data; reconstruct with --test-frames %d", held, T)
    prov_kind = (getattr(model, "provenance_", None) or {}).get("rest_kind")
    kind = recon.info.get("rest_source", {}).get("kind", "model")
    if prov_kind is not None and prov_kind != kind:
        log.warning("the model was trained on fields measured from a %s rest, this reconstruction is "
                    "measured from a %s rest", prov_kind, kind)
    from lipgen.modes.combined import CombinedModel

    # The combined model chooses its physical prior and the marker noise from the training fields.
    comb = CombinedModel(model, physics).fit(recon.fields[train])
    out["combined_choice"] = {"kind": comb.kind, "residual_share": comb.selection_.residual_share,
                              "noise_variance_mm2": comb.noise_variance_,
                              "log_likelihood": comb.selection_.log_likelihood}
    out["table51"] = table51(model, physics, recon, test, true_fields, min(10, len(model.components_)),
                             combined=comb, rest=rest)
    var = np.asarray(model.full_variance_)
    out["variance"] = {"cumulative_share": (np.cumsum(var) / model.total_variance_).tolist(),
                       "ten_modes": float(var[:10].sum() / model.total_variance_)}
    from lipgen.mesh.procedural import thesis_unit_mm

    out["thesis_unit_mm"] = thesis_unit_mm(mesh)
    out["_truth"] = truth
    out["_true_fields"] = true_fields
    return out
