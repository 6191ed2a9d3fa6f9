"""The truth subject moved by its own nonlinear physics (:mod:`lipgen.subject.layer`).

:func:`with_layer` gives a :class:`~lipgen.subject.motion.Subject` a thin StVK layer under its
surface, with per-subject materials, and calibrates each action's muscle force in the layer's own
small-strain limit so that activation 1 moves its marker by the action's target (as the linear
subject is calibrated); larger activations, the jaw and contact then respond nonlinearly.
:func:`layer_displacements` solves the frames one after the other, each warm-started from the
previous one.
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from lipgen.subject.activation import ACTIONS, action_index

__all__ = ["with_layer", "layer_displacements", "LAYER_THICKNESS_MM"]

log = logging.getLogger(__name__)

LAYER_THICKNESS_MM = {"lip": 2.0, "ridge": 1.5, "skin": 2.0, "strip": 1.0}
"""Thickness of the truth's tissue layer per region (mm): the modelled part of the lips' depth
(orbicularis and the tissue over it), thin enough for the tight curl of the ridge."""


def _node_thickness(mesh) -> np.ndarray:
    names = np.array(mesh.region_names)[mesh.regions]
    face_t = np.array([LAYER_THICKNESS_MM.get(r, 1.5) for r in names])
    t = np.full(mesh.n_nodes, np.inf)
    for k in range(3):
        np.minimum.at(t, mesh.faces[:, k], face_t)
    return t


def with_layer(subject, rng=None):
    """``subject`` with nonlinear truth physics: a :class:`~lipgen.subject.layer.Layer` and the
    per-action nodal forces (A, n, 3) calibrated on it.

    Materials per subject (from ``rng``, or the subject's seed): Poisson's ratio 0.40-0.47 and a
    volume penalty 10-30 times the shear modulus (near-incompressible soft tissue), and the same
    relative Young's moduli per region as the linear subject.
    """
    from lipgen.subject.layer import build_layer
    from lipgen.subject.sources import ACTION_TARGETS_MM, _force_patterns, _region_nodes

    rng = np.random.default_rng(subject.seed if rng is None else rng)
    mesh = subject.mesh
    y = mesh.vertices[:, 1]
    lower_lip = _region_nodes(mesh, ("lip", "ridge")) * (0.5 - 0.5 * np.tanh(y / 1.5))
    poisson = float(rng.uniform(0.40, 0.47))
    kappa = float(rng.uniform(10.0, 30.0))
    layer = build_layer(mesh, subject.stiffness, _node_thickness(mesh), poisson=poisson, kappa_ratio=kappa,
                        anchors=subject.physics.mesh.anchors, contact_pairs=subject.contact_pairs,
                        gum_nodes=lower_lip)
    n = mesh.n_nodes
    patterns = _force_patterns(mesh)
    solve = layer._factor()
    free = ~layer.fixed
    forces = np.zeros((len(ACTIONS), n, 3))
    for a, name in enumerate(ACTIONS):
        if name not in patterns or name not in ACTION_TARGETS_MM:
            continue
        marker, mm = ACTION_TARGETS_MM[name]
        if name == "jaw_open":
            mm = 2.5  # the depressor's share, as the linear subject
        lin = np.linalg.norm(subject.responses[a, mesh.marker_index(marker)])
        f = np.zeros((2 * n, 3))
        f[:n] = patterns[name]
        u = np.zeros((2 * n, 3))
        u[free] = solve(f[free].ravel()).reshape(-1, 3)  # the layer's small-strain response
        forces[a] = patterns[name] * (lin if lin > 0 else mm) / np.linalg.norm(u[mesh.marker_index(marker)])
    forces.setflags(write=False)
    info = {"poisson": poisson, "kappa_ratio": kappa, "thickness_mm": dict(LAYER_THICKNESS_MM)}
    return replace(subject, layer=layer, layer_forces=forces, layer_info=info)


def layer_displacements(subject, A: np.ndarray, progress: bool = False) -> np.ndarray:
    """(F, n, 3) displacements of the subject's surface for activations ``A`` (F, A), solved
    frame by frame with the nonlinear layer (each frame warm-started from the previous one)."""
    from tqdm import tqdm

    from lipgen.subject.sources import _jaw_rigid

    layer = subject.layer
    n = subject.mesh.n_nodes
    X2 = layer.rest
    side = A[:, action_index("jaw_shift_left")] - A[:, action_index("jaw_shift_right")]
    angles = A[:, action_index("jaw_open")] * subject.jaw_max_angle
    rigid = _jaw_rigid(X2, angles, subject.jaw_max_angle, subject.jaw_shift_mm * side)  # (F, 2n, 3)
    bw = np.concatenate([subject.border_weight, subject.border_weight])
    out = np.zeros((len(A), n, 3))
    x = X2.copy()
    for f in tqdm(range(len(A)), desc="truth physics", unit="frame", disable=not progress):
        force = np.zeros_like(X2)
        force[:n] = np.einsum("a,ani->ni", A[f], subject.layer_forces)
        prescribed = X2 + bw[:, None] * rigid[f]
        x = layer.solve(force, prescribed, x0=x, gum_target=X2 + rigid[f])
        out[f] = x[:n] - X2[:n]
    return out
