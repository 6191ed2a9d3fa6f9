"""The truth subject moved by its own nonlinear physics (:mod:`lipgen.subject.layer`).

:func:`with_layer` gives a :class:`~lipgen.subject.motion.Subject` a thin StVK layer under its
surface, with per-subject materials, and calibrates each action's muscle force in the layer's own
small-strain limit so that activation 1 moves its marker by the action's target (as the linear
subject is calibrated); larger activations, the jaw and contact then respond nonlinearly.
:func:`layer_displacements` solves the frames one after the other, each warm-started from the
previous one.

The pucker (``pucker``, ``pucker_left``, ``pucker_right``) is the orbicularis oris contracting
inside the lips, not only a pull on their surface: its fibres, running round the mouth, shorten
by an isochoric active strain (:func:`~lipgen.subject.layer.active_strain`, :data:`PUCKER_SHORTENING`
at activation 1), and the dead-load part of the action supplies the rest of its calibrated
displacement (the lips pushed forward). A surface pull alone stretched the layer over the teeth
and thinned it (lip layer -6 % at a full pucker, volume -7 %); the contraction with the
near-incompressible tissue (:func:`with_layer`'s volume penalty) thickens it instead
(``tests/test_truth_layer.py`` measures both). Ultrasound shows the lips' muscle layer thickening
as it contracts, the upper lip's more than the lower's (Vinkka-Puhakka, Kean & Heap, "Ultrasonic
investigation of the circumoral musculature", J. Anat. 166, 1989); no published figure for the
thickness change of a whole lip under a pucker was found, so nothing here is set from one.
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from lipgen._threads import single_threaded
from lipgen.subject.activation import ACTIONS, action_index

__all__ = ["with_layer", "layer_displacements", "layer_active", "LAYER_THICKNESS_MM", "PUCKER_SHORTENING"]

log = logging.getLogger(__name__)

LAYER_THICKNESS_MM = {"lip": 2.0, "ridge": 1.5, "skin": 2.0, "strip": 1.0}
"""Thickness of the truth's tissue layer per region (mm): the modelled part of the lips' depth
(orbicularis and the tissue over it), thin enough for the tight curl of the ridge."""


PUCKER_SHORTENING = 0.3
"""Share by which the orbicularis oris fibres shorten at a full pucker (activation 1): an assumed
value within skeletal muscle's working range (shortening up to 30-40 %); as a logarithmic
contraction, ``-ln(1 - 0.3)``."""

_FIBRE_ELLIPSE_MM = (25.0, 8.0)  # the fibres run along ellipses round the mouth (half width, half height)


def _fibres(mesh, faces_of_tets: np.ndarray) -> np.ndarray:
    """(T, 3) unit orbicularis fibre directions: tangent to ellipses round the mouth centre, in
    each tetrahedron's face plane."""
    V, F = mesh.vertices, mesh.faces
    c = V[F].mean(axis=1)
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    a, b = _FIBRE_ELLIPSE_MM
    t = np.stack([-c[:, 1] * a * a, c[:, 0] * b * b, np.zeros(len(c))], axis=1)
    t -= np.sum(t * n, axis=1, keepdims=True) * n
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    return t[faces_of_tets]


def _pucker_weights(mesh) -> dict[str, np.ndarray]:
    """(n,) how much each node's tissue takes part in each pucker action (as its force pattern)."""
    from lipgen.subject.sources import _region_nodes

    lips = _region_nodes(mesh, ("lip", "ridge")).astype(float)
    x = mesh.vertices[:, 0]
    out = {"pucker": lips}
    for side, sign in (("left", 1.0), ("right", -1.0)):  # as sources._independent_patterns
        out[f"pucker_{side}"] = lips / (1.0 + np.exp(-(sign * x + 3.0) / 4.0))
    return out


def layer_active(subject, a: np.ndarray) -> np.ndarray | None:
    """(T, 3, 3) inverse active strains of the layer's tetrahedra for one frame's activations
    ``a`` (A,), or None where no muscle contracts."""
    fibres, contraction = subject.layer_active
    c = a @ contraction
    if not c.any():
        return None
    from lipgen.subject.layer import active_strain

    return active_strain(fibres, c)


def _node_thickness(mesh) -> np.ndarray:
    names = np.array(mesh.region_names)[mesh.regions]
    face_t = np.array([LAYER_THICKNESS_MM.get(r, 1.5) for r in names])
    t = np.full(mesh.n_nodes, np.inf)
    for k in range(3):
        np.minimum.at(t, mesh.faces[:, k], face_t)
    return t


@single_threaded(always=True)
def with_layer(subject, rng=None):
    """``subject`` with nonlinear truth physics: a :class:`~lipgen.subject.layer.Layer` and the
    per-action nodal forces (A, n, 3) calibrated on it.

    Materials per subject (from ``rng``, or the subject's seed): Poisson's ratio 0.40-0.47 of the
    StVK part and a volume penalty 50-150 times the shear modulus, together an effective Poisson's
    ratio of 0.490-0.497 (near-incompressible soft tissue: face and tongue FE models use 0.49-0.499,
    e.g. Buchaillard, Perrier & Payan, JASA 126, 2009), and the same relative Young's moduli per
    region as the linear subject. The pucker actions also contract the orbicularis fibres (see the
    module docstring).
    """
    from lipgen.subject.layer_build import build_layer
    from lipgen.subject.sources import ACTION_TARGETS_MM, _force_patterns, _region_nodes

    rng = np.random.default_rng(subject.seed if rng is None else rng)
    mesh = subject.mesh
    y = mesh.vertices[:, 1]
    lower_lip = _region_nodes(mesh, ("lip", "ridge")) * (0.5 - 0.5 * np.tanh(y / 1.5))
    poisson = float(rng.uniform(0.40, 0.47))
    kappa = float(rng.uniform(50.0, 150.0))
    layer = build_layer(mesh, subject.stiffness, _node_thickness(mesh), poisson=poisson, kappa_ratio=kappa,
                        anchors=subject.physics.mesh.anchors, contact_pairs=subject.contact_pairs,
                        gum_nodes=lower_lip)
    n = mesh.n_nodes
    patterns = _force_patterns(mesh)
    solve = layer._factor()
    free = ~layer.fixed
    tface = np.tile(np.arange(mesh.n_faces), 3)  # each tet's face (build_layer's order)
    fibres = _fibres(mesh, tface)
    contraction = np.zeros((len(ACTIONS), len(layer.tets)))
    for name, w in _pucker_weights(mesh).items():
        contraction[action_index(name)] = -np.log1p(-PUCKER_SHORTENING) * w[mesh.faces].mean(axis=1)[tface]

    def response(f):  # the layer's small-strain response to nodal forces (2n, 3)
        u = np.zeros((2 * n, 3))
        u[free] = solve(f[free].ravel()).reshape(-1, 3)
        return u

    forces = np.zeros((len(ACTIONS), n, 3))
    for a, name in enumerate(ACTIONS):
        if name not in patterns or name not in ACTION_TARGETS_MM:
            continue
        marker, mm = ACTION_TARGETS_MM[name]
        k = mesh.marker_index(marker)
        if name == "jaw_open":
            mm = 2.5  # the depressor's share, as the linear subject
        lin = np.linalg.norm(subject.responses[a, k])
        target = lin if lin > 0 else mm
        f = np.zeros((2 * n, 3))
        f[:n] = patterns[name]
        u_f = response(f)[k]
        u_a = np.zeros(3)
        if contraction[a].any():  # the contraction's linear response: its force at rest, per unit
            eps = 1e-6
            from lipgen.subject.layer import active_strain

            g = layer.energy_grad(layer.rest, np.zeros_like(layer.rest),
                                  active=active_strain(fibres, eps * contraction[a]))[1]
            u_a = response(-g / eps)[k]
        # the force's share: |s u_f + u_a| = target at the marker (s >= 0)
        p, q = float(u_f @ u_f), float(u_f @ u_a)
        s = (-q + np.sqrt(max(q * q - p * (float(u_a @ u_a) - target**2), 0.0))) / p
        if s <= 0:
            log.warning("truth layer: %s's contraction alone moves %s by %.2f mm, beyond its %.2f mm",
                        name, marker, np.linalg.norm(u_a), target)
        forces[a] = patterns[name] * max(s, 0.0)
    forces.setflags(write=False)
    contraction.setflags(write=False)
    info = {"poisson": poisson, "kappa_ratio": kappa, "thickness_mm": dict(LAYER_THICKNESS_MM),
            "pucker_shortening": PUCKER_SHORTENING}
    return replace(subject, layer=layer, layer_forces=forces, layer_info=info,
                   layer_active=(fibres, contraction))


@single_threaded(always=True)
def layer_displacements(subject, A: np.ndarray, progress: bool = False) -> np.ndarray:
    """(F, n, 3) displacements of the subject's surface for activations ``A`` (F, A), solved
    frame by frame with the nonlinear layer (each frame warm-started from the previous one).

    One BLAS thread, always (as the linear subject's contact): the factorisations' supernodal BLAS
    would otherwise round differently with the thread count, and the truth must not depend on
    the machine; its calls are small, so a second thread only waits."""
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
    layer.restart()   # from K0, not another call's tangent: the same bytes every call
    for f in tqdm(range(len(A)), desc="truth physics", unit="frame", disable=not progress):
        force = np.zeros_like(X2)
        force[:n] = np.einsum("a,ani->ni", A[f], subject.layer_forces)
        prescribed = X2 + bw[:, None] * rigid[f]
        x = layer.solve(force, prescribed, x0=x, gum_target=X2 + rigid[f], active=layer_active(subject, A[f]))
        out[f] = x[:n] - X2[:n]
    return out
