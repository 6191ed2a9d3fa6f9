"""Thesis Table 5.1 on synthetic ground truth, with what the thesis could not measure.

The thesis (ch. 5) trained modes on 140 frames of 16 tracked markers and reported the LLSE error
per DOF on the last 10 frames from three kinds of partial observation. Its only "truth" was the
least-strain field reaching the markers. Here the truth subject (:mod:`lipgen.subject.motion`: a finer
mesh, its own stiffness, jaw hinge, lip contact) is known everywhere, so the same estimates are
also scored against the **true surface** (the truth mesh at the model's nodes: the meshes are
nested, node i of ``lip_mesh(0)`` is node i of the truth mesh), and the combined learned +
physical model of §6.1 is added.

Protocol (:func:`run_table51`)
------------------------------
1. Simulate ``n_frames`` of random gestures with head motion. The 16 markers are measured in the
   world (optionally with Gaussian noise) and mapped into the model frame with the known head pose.
2. Each frame's field is ``Physics.reach`` from the 16 marker goals on ``lip_mesh(0)`` (§4.1);
   the first ``n_train`` fields train :class:`~lipgen.modes.ModeModel` (§4.2).
3. On the test frames, each observation row is reconstructed by each estimator; the error is the
   mean squared error per hidden DOF (the DOFs neither observed nor anchored), in mm² and in the
   thesis's normalised units².
4. Outside the training span: actions held out of training test the combined model
   (:mod:`lipgen.experiments.table51_span`).

The combined model's prior kind and noise variance τ² are chosen from the training fields only,
by cross-validated marginal likelihood of their markers
(:meth:`lipgen.modes.combined.CombinedModel.fit`); it uses its own τ², and weighs the residual variance
σ² per frame by the frame's own observations (:meth:`~lipgen.modes.combined.CombinedModel.mixture`).
The column "combined_fixed" is the linear LLSE at the cross-validated σ². The other estimators of
the marker rows are given the true marker-noise variance.
"""

from __future__ import annotations

import logging
from dataclasses import asdict

import numpy as np

from lipgen.experiments.table51_protocol import (
    Observed,
    Table51Settings,
    _hidden,
    _independent,
    _motion,
    _score,
    _selection,
    fit_combined,
    make_subject,
    observation_rows,
    observe,
    row_errors,
)
from lipgen.fem import Physics
from lipgen.mesh.procedural import lip_mesh, thesis_unit_mm
from lipgen.modes.model import ModeModel
from lipgen.subject.motion import head_motion

__all__ = ["run_table51"]

log = logging.getLogger(__name__)

def _modes_curve(model, physics, data: Observed, rows, noise_var, k_max) -> dict:
    ks = list(range(1, min(k_max, len(model.full_variance_)) + 1))
    curve = {"k": ks}
    for name, d in rows.items():
        markers_only = "points" in name
        hid = _hidden(physics, d)
        curve[name] = {}
        for ref in ("reach", "truth"):
            reference = getattr(data, ref)
            measured = data.reach if markers_only else reference
            curve[name][ref] = [row_errors(model.llse(d, k, noise=noise_var if markers_only else 0.0), d,
                                           measured, reference, hid) for k in ks]
    return curve


def run_table51(settings: Table51Settings | None = None) -> dict:
    """Run the experiment; returns every figure (JSON-ready) plus the fitted model under ``"_model"``."""
    s = settings or Table51Settings()
    rng = np.random.default_rng(s.seed)
    subject = make_subject(s)
    mesh = lip_mesh(0)
    physics = Physics(mesh)
    acts, residual = _motion(s, subject, s.n_frames, s.seed)
    head = head_motion(s.n_frames, s.seed) if s.head else None
    data = observe(subject, physics, acts, head, s.marker_noise_mm, rng, residual, s.marker_noise_px)
    # the estimators are given the measurement-noise variance per coordinate (mm²); through the
    # rig it is anisotropic, so its mean over the training frames (as table51_splits)
    noise_var = (s.marker_noise_mm ** 2 if s.marker_noise_px == 0
                 else float(np.mean(data.error[:s.n_train] ** 2)))
    model = ModeModel(s.n_modes).fit(data.reach[:s.n_train], mesh=mesh)
    test = Observed(*(a[s.n_train:] for a in (data.goals, data.reach, data.truth, data.activations)))
    rows = observation_rows(mesh)
    combined = fit_combined(model, physics, data.reach[:s.n_train])
    from lipgen.experiments.table51_span import outside_span

    oos = outside_span(s, subject, physics, noise_var, rng)
    log.info("table 5.1: scoring %d rows", len(rows))
    table = _score(model, physics, test, rows, noise_var, combined)
    curve = _modes_curve(model, physics, test, rows, noise_var, s.max_modes_curve)
    anchored = physics.anchored_dofs
    floor = float(np.mean(test.truth.reshape(len(test.truth), -1)[:, anchored] ** 2))
    return {
        "settings": asdict(s), "mm_per_unit": thesis_unit_mm(mesh), "subject_seed": subject.subject_seed,
        "subject_shape": None if subject.shape is None else subject.shape.to_dict(),
        "truth_physics": "linear" if subject.layer is None else "layer",
        "motion_sources": "independent" if _independent(s) else "gestures",
        "n_nodes_model": mesh.n_nodes, "n_nodes_truth": subject.mesh.n_nodes,
        "variance_captured": float(np.sum(model.explained_variance_ratio_)),
        "cumulative_variance": np.cumsum(model.full_variance_ / model.total_variance_).tolist(),
        "reach_vs_truth_mse": float(np.mean((data.reach - data.truth).reshape(len(data.reach), -1)
                                            [:, physics.free_dofs] ** 2)),
        "anchored_truth_mse": floor, "noise_variance": noise_var,
        "selection": _selection(combined["combined"]),
        "table": table, "modes_curve": curve, "outside_span": oos,
        "_model": model, "_mesh": mesh,
    }
