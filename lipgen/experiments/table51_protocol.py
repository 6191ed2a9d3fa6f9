"""The pieces of the Table 5.1 protocol: settings, observation, estimators and scoring.

Used by :func:`lipgen.experiments.table51.run_table51` (the thesis's protocol, its docstring
describes it), :mod:`lipgen.experiments.table51_span` (outside the training span) and
:mod:`lipgen.experiments.table51_splits` (utterance and subject splits).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np

from lipgen.fem import Physics, dofs
from lipgen.modes.combined import CombinedModel, default_residual_variance
from lipgen.modes.llse import LLSE, PhysicsCovariance
from lipgen.modes.model import ModeModel
from lipgen.subject.motion import ACTIONS, default_subject, random_activations, simulate

__all__ = ["Table51Settings", "Observed", "observe", "observation_rows", "estimators", "fit_combined",
           "row_errors", "make_subject", "measure_through_rig", "COLUMNS", "SHARES"]

log = logging.getLogger(__name__)

SHARES = (0.001, 0.003, 0.01, 0.03, 0.1, 0.3, 1.0)
"""Residual shares of the test-set sensitivity sweep (reported, never used for the choice)."""

COLUMNS = ("modes", "full", "physics_force", "physics_energy", "combined", "combined_fixed",
           "combined_energy")
"""Estimators: the first k modes; the full sample covariance; the physics alone with the thesis's
K_s⁻² (min-norm force, = ``Physics.reach``) and with K_s⁻¹ (least strain energy); the combined
model (k modes + physical residual; kind and τ² chosen by :meth:`CombinedModel.fit`, σ² unknown
per frame: :meth:`CombinedModel.mixture`); the same with the one σ² of :meth:`CombinedModel.fit`
(linear, :meth:`CombinedModel.llse`); and that with the K_s⁻¹ prior imposed."""


@dataclass(frozen=True)
class Table51Settings:
    """Settings of the experiment (the defaults are the thesis's)."""

    n_frames: int = 150
    n_train: int = 140
    n_modes: int = 10
    seed: int = 0
    truth_resolution: int = 1
    marker_noise_mm: float = 0.0
    marker_noise_px: float = 0.0
    """Pixel noise (std per image coordinate) of the markers in both views of the default
    camera-mirror rig, triangulated (:func:`measure_through_rig`): the rig's own, anisotropic
    measurement error (depth worst), as the thesis's measured data had."""
    head: bool = True
    max_modes_curve: int = 40
    held_out_test: tuple[str, ...] = ("lip_corner_puller", "funneler")
    oos_frames: int = 40
    oos_realisations: int = 8
    preset: str = "easy"
    """Subject conditions (:mod:`lipgen.dataset.presets`): ``easy`` is the model's shape, dots on
    its nodes and the linear truth; ``default`` the subject's own shape and dots; ``hard`` adds
    the nonlinear tissue layer (slow)."""
    subject_seed: int | None = None
    """The subject's shape and dots (presets ``default``/``hard``; their default seed if None)."""

    def __post_init__(self) -> None:
        from lipgen.dataset.presets import get_preset

        p = get_preset(self.preset)
        if self.subject_seed is not None and not p.subject.own_shape:
            raise ValueError(f"preset {self.preset!r} uses the model's own shape; a subject seed needs "
                             "preset 'default' or 'hard'")
        if not 1 <= self.n_modes < self.n_train < self.n_frames:
            raise ValueError(f"need 1 <= n_modes < n_train < n_frames, got {self.n_modes}, "
                             f"{self.n_train}, {self.n_frames}")
        if self.oos_realisations < 1:
            raise ValueError(f"oos_realisations must be >= 1, got {self.oos_realisations}")
        for name in ("marker_noise_mm", "marker_noise_px"):
            v = getattr(self, name)
            if not 0 <= v < float("inf"):  # NaN ran to the end (px) or failed late unnamed (mm)
                raise ValueError(f"{name} must be a finite number >= 0, got {v}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int | np.integer) or self.seed < 0:
            raise ValueError(f"seed must be a whole number >= 0, got {self.seed!r}")
        for name in self.held_out_test:
            if name not in ACTIONS:
                raise ValueError(f"unknown action {name!r}; the known actions are {', '.join(ACTIONS)}")


@dataclass(frozen=True)
class Observed:
    """Model-frame data of a run of frames, on the reconstruction mesh (n0 nodes).

    Attributes
    ----------
    goals : (F, 16, 3) float
        Measured marker displacements from rest (mm), as the thesis's training data.
    reach : (F, n0, 3) float
        Least-strain fields reaching the goals (the thesis's "truth").
    truth : (F, n0, 3) float
        The true displacement of the model's nodes.
    activations : (F, A) float
    error : (F, 16, 3) float or None
        The measurement error of the markers (measured minus true, model frame, mm).
    """

    goals: np.ndarray
    reach: np.ndarray
    truth: np.ndarray
    activations: np.ndarray
    error: np.ndarray | None = None


def measure_through_rig(world, noise_px: float, rng=None, rig=None) -> np.ndarray:
    """World points as the camera-mirror rig measures them: projected into both views, Gaussian
    pixel noise added, triangulated by ray midpoints (thesis §3).

    The rig's two views meet at an angle (44 degrees for :func:`~lipgen.rig.camera.default_rig`),
    so the error is anisotropic: depth along the views' bisector is measured worst.

    Parameters
    ----------
    world : (..., 3) float
        True world points, mm.
    noise_px : float
        Standard deviation of the pixel noise per image coordinate in each view (>= 0).
    rng : int or numpy.random.Generator, optional
    rig : lipgen.rig.camera.MirrorRig, optional
        Defaults to :func:`~lipgen.rig.camera.default_rig`.

    Returns
    -------
    (..., 3) float
        The triangulated points, mm.
    """
    from lipgen.rig.camera import default_rig

    if noise_px < 0:
        raise ValueError(f"noise_px must be >= 0, got {noise_px}")
    rig = default_rig() if rig is None else rig
    uv, _, _ = rig.project(np.asarray(world, float))
    uv = uv + np.random.default_rng(rng).normal(scale=noise_px, size=uv.shape)
    points, _ = rig.triangulate(uv[1], uv[0])  # views: (virtual, real)
    return points


def observe(subject, physics: Physics, activations, head=None, noise_mm: float = 0.0, rng=None,
            residual=None, noise_px: float = 0.0) -> Observed:
    """Simulate ``activations`` (plus a ``residual`` deformation (F, n, 3) in mm of the truth mesh,
    :func:`lipgen.subject.independent.residual_motion`) and measure the markers as the thesis's
    pipeline would: with isotropic world noise ``noise_mm`` (mm), or pixel noise ``noise_px`` in
    the rig's views, triangulated (:func:`measure_through_rig`)."""
    mesh = physics.mesh
    n0 = mesh.n_nodes
    if subject.mesh.n_nodes < n0:
        raise ValueError("the truth mesh does not nest the model mesh (it has fewer nodes)")
    # displacements are from the subject's own rest (its shape may differ from the model's)
    rest = subject.mesh.vertices[:n0]
    motion = simulate(subject, activations, head)
    if residual is not None:
        motion = replace(motion, vertices=motion.vertices + residual)
    true_world = motion.markers_world
    world = true_world
    if noise_mm > 0:
        world = world + np.random.default_rng(rng).normal(scale=noise_mm, size=world.shape)
    if noise_px > 0:
        world = measure_through_rig(world, noise_px, rng)
    R, t = motion.poses[:, :3, :3], motion.poses[:, :3, 3]
    model = np.einsum("fji,fkj->fki", R, world - t[:, None])  # known head pose: R^T (X - t)
    goals = model - motion.rest_markers
    reach, _ = physics.reach(dofs(mesh.markers), goals.reshape(len(goals), -1))
    error = np.einsum("fji,fkj->fki", R, world - true_world)
    return Observed(goals, reach, motion.vertices[:, :n0] - rest, motion.activations, error)


def observation_rows(mesh) -> dict[str, np.ndarray]:
    """Observed DOFs of each row: Table 5.1's three, plus its "all points" read as all free nodes."""
    free = np.setdiff1d(np.arange(mesh.n_nodes), mesh.anchors)
    return {
        "xyz (8 points)": dofs(mesh.markers[:8]),
        "yz (16 points)": dofs(mesh.markers, "yz"),
        "xy (16 points)": dofs(mesh.markers, "xy"),
        "yz (all nodes)": dofs(free, "yz"),
        "xy (all nodes)": dofs(free, "xy"),
    }


def fit_combined(model: ModeModel, physics: Physics, train_fields, n_modes: int | None = None) -> dict:
    """The two combined columns, chosen from the training fields (:meth:`CombinedModel.fit`):
    ``"combined"`` picks the prior kind, ``"combined_energy"`` is held to K_s⁻¹."""
    k = len(model.components_) if n_modes is None else n_modes
    return {"combined": CombinedModel(model, physics, n_modes=k).fit(train_fields),
            "combined_energy": CombinedModel(model, physics, n_modes=k).fit(train_fields, kinds=("energy",))}


def estimators(model: ModeModel, physics: Physics, d, noise: float = 0.0, n_modes: int | None = None,
               combined: dict | None = None, combined_noise=None) -> dict:
    """The estimator of each column of :data:`COLUMNS` for observed DOFs ``d`` (an
    :class:`~lipgen.modes.llse.LLSE`, or a :class:`~lipgen.modes.mixture.ScaleMixtureLLSE` for "combined").

    ``noise`` (mm²) is given to the learned and physics-only columns; ``combined`` is
    :func:`fit_combined`'s result (without it the combined columns use the default share and no
    noise), and ``combined_noise`` their noise variance (their own estimate by default).
    """
    k = len(model.components_) if n_modes is None else n_modes
    phys = {kind: PhysicsCovariance(physics, default_residual_variance(model, physics, 1.0, kind=kind), kind)
            for kind in ("force", "energy")}
    if combined is None:
        combined = {"combined": CombinedModel(model, physics, n_modes=k),
                    "combined_energy": CombinedModel(model, physics, n_modes=k, kind="energy")}
    return {
        "modes": model.llse(d, k, noise=noise),
        "full": model.llse(d, "full", noise=noise),
        "physics_force": LLSE.build(phys["force"], d, noise=noise),
        "physics_energy": LLSE.build(phys["energy"], d, noise=noise),
        "combined": combined["combined"].mixture(d, noise=combined_noise),
        "combined_fixed": combined["combined"].llse(d, noise=combined_noise),
        "combined_energy": combined["combined_energy"].llse(d, noise=combined_noise),
    }


def row_errors(est: LLSE, d: np.ndarray, measured: np.ndarray, reference: np.ndarray,
               hidden: np.ndarray, relative: bool = False) -> float:
    """Error per hidden DOF (mm², :func:`lipgen.evaluate.metric.per_dof_error`, the definition
    ``lipgen evaluate`` uses) of the estimate from ``measured[:, d]`` against ``reference``; with
    ``relative``, over the reference's own mean square on those DOFs."""
    from lipgen.evaluate.metric import per_dof_error, relative_error

    F = len(reference)
    X = est(measured.reshape(F, -1)[:, d]).reshape(F, -1)
    return (relative_error if relative else per_dof_error)(X, reference, hidden)


def _hidden(physics: Physics, d: np.ndarray) -> np.ndarray:
    from lipgen.evaluate.metric import hidden_dofs

    return hidden_dofs(physics.free_dofs, d)


def _score(model, physics, data: Observed, rows, noise_var, combined, columns=COLUMNS) -> dict:
    """{row: {column: {"reach": mse, "truth": mse}}} for the frames of ``data``."""
    out = {}
    for name, d in rows.items():
        markers_only = "points" in name  # the "(all nodes)" rows observe noise-free fields
        ests = estimators(model, physics, d, noise_var if markers_only else 0.0, combined=combined,
                          combined_noise=None if markers_only else 0.0)
        out[name] = {}
        for col in columns:
            scores = {}
            for ref in ("reach", "truth"):
                reference = getattr(data, ref)
                measured = data.reach if markers_only else reference  # markers are what was measured
                scores[ref] = row_errors(ests[col], d, measured, reference, _hidden(physics, d))
            scores["truth_relative"] = row_errors(ests[col], d, measured, data.truth, _hidden(physics, d),
                                                  relative=True)
            out[name][col] = scores
    return out


def _independent(s: Table51Settings) -> bool:
    from lipgen.dataset.presets import get_preset

    return get_preset(s.preset).motion.sources == "independent"


def _motion(s: Table51Settings, subject, n: int, seed: int):
    """Activations (n, A) and the residual deformation ((n, N, 3) or None) of the preset's motion."""
    if not _independent(s):
        return random_activations(n, seed), None
    from lipgen.subject.independent import independent_activations, residual_motion

    a_rng, r_rng = np.random.default_rng(seed).spawn(2)
    return independent_activations(n, a_rng), residual_motion(subject, n, r_rng)


def _selection(cm: CombinedModel) -> dict:
    sel = cm.selection_
    keys = ("kind", "residual_share", "residual_variance", "noise_variance", "log_likelihood", "by_kind",
            "n_folds")
    return {k: getattr(sel, k) for k in keys}


def make_subject(s: Table51Settings):
    """The truth subject of the settings' preset."""
    from lipgen.dataset.presets import get_preset

    p = get_preset(s.preset).subject
    sseed = (p.default_subject_seed if s.subject_seed is None else s.subject_seed) if p.own_shape else None
    subject = default_subject(s.seed, s.truth_resolution, subject_seed=sseed)
    if p.nonlinear_physics:
        from lipgen.subject.truth import with_layer

        subject = with_layer(subject)
    return subject
