"""The synthetic subject: muscle-like actions on a finer, differently built lip model.

The ground truth must not come from the model being fitted ("avoid the inverse crime",
DESIGN.md). The truth subject therefore differs from the reconstruction model (``lip_mesh(0)``
with default stiffness, grounded at the strip only) in four ways:

- **a finer mesh**: ``lip_mesh(1)`` by default (the first nodes of a resolution are the nodes
  of every coarser one, at the same points, so the truth can be compared node for node);
- **its own stiffness**: :data:`TRUTH_STIFFNESS`, softer lower lip than upper lip, varied per
  subject by the seed;
- **its own boundary conditions**: the outer skin border is held by the face around it, fixed to
  the skull at the top and carried by the jaw at the bottom, blended in between (the model holds
  the whole border still);
- **nonlinear motion**: the jaw rotates about a hinge axis near the ear, with a forward glide
  growing with the square of the opening; the border follows that rigid motion and the lower lip
  is carried along by its attachment to the gum, so points move on arcs; every displacement is
  finally wrapped onto the cylinder of the dental arch, so that the corners slide round the face
  on arcs rather than on straight lines.

Each action is a force pattern (muscle-like pulls, see :data:`ACTIONS`) whose elastic response
is scaled so that activation 1 gives a plausible displacement in mm (:data:`ACTION_TARGETS_MM`).
The upper-lip raiser, corner puller and corner depressor also come one-sided (``_left`` /
``_right``, the same muscle on one side, calibrated on that side's marker), and the jaw can shift
sideways (``jaw_shift_left`` / ``_right``, a rigid shift of :data:`JAW_SHIFT_MM` that the border
and the gum pass on to the lips), so that asymmetric expressions occur as on real faces. The
displacement of a frame is linear in the activations except for the jaw, the contact and the wrap.

Frames
------
The model frame is the head's frame (mm; +x subject's left, +y up, +z out of the face, origin at
the mouth centre at rest). A head pose ``P`` (4x4) maps it to the world: ``X_world = R X + t``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from lipgen._threads import single_threaded
from lipgen._validate import as_float_array
from lipgen.mesh.lipmesh import LipMesh
from lipgen.subject.activation import (
    ACTIONS,
    DEFAULT_FPS,
    VISEMES,
    _activation_array,
    action_index,
    head_motion,
    parse_script,
    random_activations,
    viseme_activations,
)
from lipgen.subject.sources import (
    ACTION_TARGETS_MM,
    JAW_SHIFT_MM,
    TRUTH_STIFFNESS,
    _border_nodes,
    _calibrate_jaw,
    _contact_pairs,
    _force_patterns,
    _jaw_rigid,
    _region_nodes,
    _smoothstep,
    _wrap,
)

__all__ = ["ACTIONS", "VISEMES", "ACTION_TARGETS_MM", "TRUTH_STIFFNESS", "Subject", "Motion",
           "default_subject", "simulate", "random_activations", "viseme_activations",
           "head_motion", "parse_script", "action_index", "JAW_SHIFT_MM"]

@dataclass(frozen=True, eq=False)
class Subject:
    """A synthetic subject: the truth mesh, its physics and its calibrated actions.

    Build it with :func:`default_subject`. Attributes (arrays read-only in spirit):

    Attributes
    ----------
    mesh : LipMesh
        The truth mesh at rest (model frame, mm), with the default anchors and the 16 markers.
    physics : lipgen.Physics
        Its physics, grounded at the strip's anchors *and* the outer skin border.
    stiffness : (m,) float
        Per-face E of the truth.
    border_weight : (n,) float
        How much each border node follows the jaw (0 skull ... 1 jaw); 0 off the border.
    responses : (A, n, 3) float
        Elastic displacement (mm) of each action at activation 1, without the jaw's rotation.
    carry : (n, 3) float
        Force pattern of the gum carrying the lower lip, per mm of jaw displacement.
    jaw_max_angle : float
        Jaw opening (rad) at jaw_open = 1.
    seed : int
    contact_pairs : (p, 2) int
        Facing nodes of the upper and lower inner lip contour, which may touch but not cross.
    contact_response : (p, n, 3) float
        Displacement under a unit pair of contact forces pushing pair k apart (mm per unit force).
    jaw_shift_mm : float
        Sideways jaw shift (mm) at ``jaw_shift_left`` = 1.
    shape : lipgen.subject.shape.ShapeParams or None
        The rest shape the mesh was warped to (None: the model's own shape).
    dots : lipgen.subject.inkdots.SurfaceDots or None
        The ink dots as surface points (None: on the marker nodes).
    subject_seed : int or None
        The seed the shape and dots were drawn from.
    layer, layer_forces, layer_info, layer_active
        The nonlinear truth physics (:func:`lipgen.subject.truth.with_layer`), if any: then
        :func:`simulate` solves it instead of the linear responses. ``layer_active`` is (fibres
        (T, 3), contraction (A, T)): the muscle fibre direction of each tetrahedron and its
        logarithmic shortening per unit activation of each action.
    """

    mesh: LipMesh
    physics: object
    stiffness: np.ndarray
    border_weight: np.ndarray
    responses: np.ndarray
    carry: np.ndarray
    jaw_max_angle: float
    seed: int
    contact_pairs: np.ndarray = None
    contact_response: np.ndarray = None
    jaw_shift_mm: float = JAW_SHIFT_MM
    shape: object = None
    dots: object = None
    subject_seed: int | None = None
    layer: object = None
    layer_forces: np.ndarray = None
    layer_info: dict = None
    layer_active: tuple = None

    @property
    def n_nodes(self) -> int:
        return self.mesh.n_nodes

    def jaw_displacement(self, angles, shifts=None) -> np.ndarray:
        """(b, n, 3) elastic displacement (mm) caused by jaw openings ``angles`` (b,) in rad and
        sideways jaw shifts ``shifts`` (b,) in mm (+x: the subject's left; none by default)."""
        angles = np.atleast_1d(np.asarray(angles, float))
        X = self.mesh.vertices
        rigid = _jaw_rigid(X, angles, self.jaw_max_angle, shifts)  # (b, n, 3)
        held = self.border_weight[None, :, None] * rigid  # prescribed on the border, 0 elsewhere
        force = self.carry[None] * rigid
        K = self.physics.K
        rhs = force.reshape(len(angles), -1).T - K @ held.reshape(len(angles), -1).T
        return self.physics.solve(rhs).T.reshape(rigid.shape) + held

    def displacements(self, activations) -> np.ndarray:
        """(F, n, 3) vertex displacements in the model frame (mm) for activations (F, A)."""
        A = _activation_array(activations)
        lin = np.einsum("fa,ani->fni", A, self.responses)
        side = A[:, action_index("jaw_shift_left")] - A[:, action_index("jaw_shift_right")]
        shift = self.jaw_shift_mm * side
        lin += self.jaw_displacement(A[:, action_index("jaw_open")] * self.jaw_max_angle, shift)
        if self.contact_pairs is not None and len(self.contact_pairs):
            lin += np.einsum("fp,pni->fni", self._contact_forces(lin), self.contact_response)
        return _wrap(self.mesh.vertices, lin) - self.mesh.vertices

    @single_threaded(always=True)
    def _contact_forces(self, U: np.ndarray) -> np.ndarray:
        """(F, p) non-negative forces that keep the inner lip contours from crossing (an LCP).

        Pair k's vertical gap is ``g0 + G λ``; find λ >= 0 with gap >= 0 and λ·gap = 0 by an
        active-set iteration (exact for this small, symmetric positive definite G).

        One BLAS thread, always: the truth must not depend on the machine. OpenBLAS's SkylakeX
        kernels split these small solves and products across two threads with another rounding
        (frames of a 30-frame clip differed by up to 7e-15 mm from one thread's), and the many tiny
        calls cost 5x the CPU on two threads under load.
        """
        up, lo = self.contact_pairs[:, 0], self.contact_pairs[:, 1]
        X = self.mesh.vertices
        g0 = (X[up, 1] + U[:, up, 1]) - (X[lo, 1] + U[:, lo, 1])
        R = self.contact_response
        G = R[:, up, 1].T - R[:, lo, 1].T  # (p, p): gap change per unit force of each pair
        lam = np.zeros_like(g0)
        for f in np.flatnonzero((g0 < 0).any(axis=1)):
            active = g0[f] < 0
            for _ in range(4 * len(active)):
                x = np.zeros(len(active))
                x[active] = np.linalg.solve(G[np.ix_(active, active)], -g0[f, active])
                gap = g0[f] + G @ x
                neg, pen = active & (x < 0), ~active & (gap < -1e-12)
                if not neg.any() and not pen.any():
                    break
                active = (active & ~neg) | pen
            lam[f] = np.maximum(x, 0.0)
        return lam


def default_subject(seed: int = 0, resolution: int = 1, shape=None,
                    subject_seed: int | None = None) -> Subject:
    """The truth subject on ``lip_mesh(resolution)``; ``seed`` varies its stiffness and gains.

    Seed 0 gives exactly :data:`TRUTH_STIFFNESS` and :data:`ACTION_TARGETS_MM`; other seeds
    scale each region's E and each target by a factor drawn from a log-normal of 10-15 %.
    ``shape`` (a :class:`lipgen.subject.shape.ShapeParams`, e.g. ``sample_shape(subject_seed)``)
    warps the rest mesh to that subject's own lips (:func:`lipgen.subject.shape.shaped_mesh`);
    without it the truth's rest shape is the model's. ``subject_seed`` draws the shape (unless
    given) and places the ink dots at surface points 1-2 mm from the model's markers
    (:func:`lipgen.subject.inkdots.place_dots`); without it the dots sit on the marker nodes.
    """
    from lipgen.fem import Physics
    from lipgen.mesh.procedural import lip_mesh
    from lipgen.subject.shape import ShapeParams, sample_shape, shaped_mesh

    if int(resolution) < 1:
        raise ValueError(f"the truth subject needs a finer mesh than the model's (resolution 0); "
                         f"got resolution {resolution}. Use 1 or more.")
    if shape is not None and not isinstance(shape, ShapeParams):
        raise TypeError(f"shape must be a ShapeParams (lipgen.subject.shape.sample_shape) or None, got "
                        f"{type(shape).__name__}")
    rng = np.random.default_rng(seed)
    if subject_seed is not None and shape is None:
        shape = sample_shape(subject_seed)
    base = lip_mesh(int(resolution))
    mesh = base if shape is None else shaped_mesh(base, shape)
    dots = None
    if subject_seed is not None:
        from lipgen.subject.inkdots import place_dots

        dots = place_dots(mesh, lip_mesh(0), np.random.default_rng([int(subject_seed), 0xD075]))
    region_scale = {r: 1.0 if seed == 0 else float(np.exp(rng.normal(0, 0.1))) for r in TRUTH_STIFFNESS}
    target_scale = {a: 1.0 if seed == 0 else float(np.exp(rng.normal(0, 0.15))) for a in ACTIONS}
    names = np.array(mesh.region_names)[mesh.regions]
    E = np.array([TRUTH_STIFFNESS[r] * region_scale[r] for r in names])
    centroid_y = mesh.vertices[mesh.faces].mean(axis=1)[:, 1]
    E[(centroid_y < 0) & np.isin(names, ("lip", "ridge"))] *= 0.75  # a softer lower lip
    border = _border_nodes(mesh)
    held = replace(mesh, anchors=np.union1d(mesh.anchors, np.flatnonzero(border)))
    physics = Physics(held, stiffness=E)
    y = mesh.vertices[:, 1]
    border_weight = np.where(border, _smoothstep((5.0 - y) / 25.0), 0.0)

    patterns = _force_patterns(mesh)
    zero = np.zeros((mesh.n_nodes, 3))  # the jaw shifts are rigid jaw motions, not muscle forces
    raw = physics.displace(np.stack([patterns.get(a, zero) for a in ACTIONS]))
    scale = np.zeros(len(ACTIONS))
    for a, name in enumerate(ACTIONS):
        if name not in ACTION_TARGETS_MM:
            continue
        marker, mm = ACTION_TARGETS_MM[name]
        mm = (2.5 if name == "jaw_open" else mm) * target_scale[name]  # the depressor's share
        scale[a] = mm / np.linalg.norm(raw[a, mesh.marker_index(marker)])
    responses = raw * scale[:, None, None]

    lower_lip = _region_nodes(mesh, ("lip", "ridge")) * (0.5 - 0.5 * np.tanh(y / 1.5))
    shift_mm = JAW_SHIFT_MM * target_scale["jaw_shift_left"]
    subject = Subject(mesh, physics, E, border_weight, responses, np.zeros((mesh.n_nodes, 3)), 1.0, int(seed),
                      jaw_shift_mm=shift_mm)
    subject = _calibrate_jaw(subject, lower_lip, ACTION_TARGETS_MM["jaw_open"][1] * target_scale["jaw_open"])
    pairs = _contact_pairs(base)  # by node: the shaped lips are no longer mirror images in y
    push = np.zeros((len(pairs), mesh.n_nodes, 3))
    push[np.arange(len(pairs)), pairs[:, 0], 1] = 1.0  # the upper lip pushed up ...
    push[np.arange(len(pairs)), pairs[:, 1], 1] = -1.0  # ... and the lower lip down
    subject = replace(subject, contact_pairs=pairs, contact_response=physics.displace(push), shape=shape,
                      dots=dots, subject_seed=None if subject_seed is None else int(subject_seed))
    for arr in (subject.stiffness, subject.border_weight, subject.responses, subject.carry,
                subject.contact_pairs, subject.contact_response):
        arr.setflags(write=False)
    return subject


@dataclass(frozen=True, eq=False)
class Motion:
    """Ground-truth frames of a synthetic subject.

    Attributes
    ----------
    mesh : LipMesh
        The truth mesh at rest (model frame, mm); its markers and nose define those below.
    vertices : (F, n, 3) float
        Vertex positions in the model (head) frame, mm.
    poses : (F, 4, 4) float
        Head pose, model -> world: ``X_world = poses[f, :3, :3] @ X + poses[f, :3, 3]``.
    activations : (F, A) float
        Activation of each action of :attr:`actions` (1 = the calibrated full action).
    fps : float
        Frames per second.
    actions : tuple of str
        Column names of :attr:`activations` (:data:`ACTIONS`).
    dots : lipgen.subject.inkdots.SurfaceDots or None
        The subject's ink dots as surface points; None: the dots are the marker nodes.
    """

    mesh: LipMesh
    vertices: np.ndarray
    poses: np.ndarray
    activations: np.ndarray
    fps: float = DEFAULT_FPS
    actions: tuple[str, ...] = ACTIONS
    dots: object = None

    @property
    def n_frames(self) -> int:
        return len(self.vertices)

    @property
    def times(self) -> np.ndarray:
        """(F,) seconds."""
        return np.arange(self.n_frames) / self.fps

    @property
    def displacements(self) -> np.ndarray:
        """(F, n, 3) displacement from rest in the model frame, mm."""
        return self.vertices - self.mesh.vertices

    @property
    def markers(self) -> np.ndarray:
        """(F, 16, 3) marker (ink dot) positions in the model frame, mm (order of ``mesh.marker_names``)."""
        if self.dots is None:
            return self.vertices[:, self.mesh.markers]
        from lipgen.subject.inkdots import dot_positions

        return dot_positions(self.dots, self.mesh.faces, self.vertices)

    @property
    def rest_markers(self) -> np.ndarray:
        """(16, 3) the marker (ink dot) positions at the subject's rest, model frame, mm."""
        if self.dots is None:
            return self.mesh.vertices[self.mesh.markers]
        from lipgen.subject.inkdots import dot_positions

        return dot_positions(self.dots, self.mesh.faces, self.mesh.vertices)

    def to_world(self, points) -> np.ndarray:
        """Model-frame points ``(F, k, 3)`` (or ``(k, 3)``, the same every frame) -> world, mm."""
        P = np.asarray(points, float)
        if P.ndim == 2:
            P = np.broadcast_to(P, (self.n_frames, *P.shape))
        return np.einsum("fij,fkj->fki", self.poses[:, :3, :3], P) + self.poses[:, None, :3, 3]

    @property
    def vertices_world(self) -> np.ndarray:
        """(F, n, 3) vertex positions in the world, mm."""
        return self.to_world(self.vertices)

    @property
    def markers_world(self) -> np.ndarray:
        """(F, 16, 3) marker positions in the world, mm."""
        return self.to_world(self.markers)

    @property
    def nose_world(self) -> np.ndarray:
        """(F, 3) the nose mark in the world (fixed to the head: ``mesh.nose`` in the model frame), mm."""
        return self.to_world(self.mesh.nose[None])[:, 0]


def simulate(subject: Subject, activations, head=None, fps: float = DEFAULT_FPS,
             progress: bool = False) -> Motion:
    """Ground-truth frames of ``subject`` for ``activations``.

    Parameters
    ----------
    subject : Subject
        From :func:`default_subject`.
    activations : (F, A) float or mapping action -> (F,) float
        Columns in :data:`ACTIONS` order, values in [0, 2]; e.g. :func:`random_activations` or
        :func:`viseme_activations`. Unknown action names raise ``ValueError``.
    head : (F, 4, 4) float, optional
        Model-to-world head poses (:func:`head_motion`); identity (world = model frame) if omitted.
    fps : float
        Frame rate recorded in the result.
    """
    A = _activation_array(activations)
    F = len(A)
    if head is None:
        poses = np.tile(np.eye(4), (F, 1, 1))
    else:
        poses = as_float_array(head, "head", (F, 4, 4))
        R = poses[:, :3, :3]
        if not (np.allclose(R @ R.transpose(0, 2, 1), np.eye(3), atol=1e-9)
                and np.allclose(np.linalg.det(R), 1.0, atol=1e-9)
                and np.allclose(poses[:, 3], [0, 0, 0, 1])):
            raise ValueError("head poses must be rigid 4x4 transforms (rotation with det +1, last row "
                             "0 0 0 1); see lipgen.subject.motion.head_motion")
    if subject.layer is not None:
        from lipgen.subject.truth import layer_displacements

        V = subject.mesh.vertices + layer_displacements(subject, A, progress=progress)
    else:
        V = subject.mesh.vertices + subject.displacements(A)
    for arr in (V, poses, A):
        arr.setflags(write=False)
    return Motion(subject.mesh, V, poses, A, float(fps), ACTIONS, subject.dots)
