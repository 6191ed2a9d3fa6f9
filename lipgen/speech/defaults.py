"""The default lips of lip sync, shipped precomputed, and the subject's motion on a model's nodes.

Lip sync projects the synthetic subject's motion (:class:`lipgen.subject.motion.Subject` on
``lip_mesh(r + 1)``, at least ``lip_mesh(1)``) onto the modes of a model of ``lip_mesh(r)``.
Building that subject (a finite-element model, its action responses, the jaw's calibration)
and learning the default modes cost about half a second and the imports of scipy, while the
result never changes between runs. So:

- :class:`NodeMotion` is the subject's motion on a subset of its nodes: the model's nodes and
  the inner-contour nodes of the lip contact. The motion is linear in the muscle-like actions
  and in four terms of the jaw's rigid motion (``cos a - 1``, ``sin a``, the glide ``(a/a_max)²``
  and the sideways shift), up to the contact forces and the wrap around the dental arch, which
  act node by node; so the whole motion of those nodes follows from the subject's responses on
  them alone. :meth:`NodeMotion.displacements` equals ``Subject.displacements(A)[:, :n]`` to
  round-off (tested), without a single solve.
- The default lips (ten modes of ``lip_mesh(0)`` learned from 240 frames, 8 s, of the seed-0
  subject's random gestures, the mesh, and the seed-0 subject's :class:`NodeMotion`) are files
  in ``lipgen/speech/data/`` written by :func:`save_default_lips`. A test rebuilds them from
  the code and compares, so a change to the subject or the mesh that alters them fails until
  they are written again (``python -c "from lipgen.speech.defaults import save_default_lips;
  save_default_lips()"``).
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from lipgen.subject.activation import ACTIONS, action_index

__all__ = ["DATA_DIR", "NodeMotion", "node_motion", "build_default_lips", "save_default_lips",
           "load_default_lips"]

log = logging.getLogger(__name__)

DATA_DIR = Path(__file__).resolve().parent / "data"
"""Folder of the shipped default lips (``modes.npz``, ``mesh.npz``, ``motion.npz``)."""

_KIND, _SCHEMA = "lipgen.speech.NodeMotion", 1
_FILES = ("modes.npz", "mesh.npz", "motion.npz")


@dataclass(frozen=True, eq=False)
class NodeMotion:
    """The synthetic subject's motion on ``m`` of its nodes, the first ``n_out`` of them output.

    Attributes
    ----------
    vertices : (m, 3) float
        Rest positions of the kept nodes (mm).
    responses : (A, m, 3) float
        Displacement (mm) of each action of :data:`~lipgen.subject.activation.ACTIONS` at 1.
    jaw_basis : (4, m, 3) float
        Elastic displacement (mm) for the four terms of the jaw's rigid motion:
        ``cos(a) - 1``, ``sin(a)``, ``(a / jaw_max_angle)²`` and the shift (mm).
    jaw_max_angle : float
        Jaw opening (rad) at ``jaw_open = 1``.
    jaw_shift_mm : float
        Sideways jaw shift (mm) at ``jaw_shift_left = 1``.
    contact_pairs : (p, 2) int
        [upper, lower] kept-node indices of the lip contact.
    contact_response : (p, m, 3) float
        Displacement (mm) per unit contact force of each pair.
    n_out : int
        The first ``n_out`` kept nodes are those :meth:`displacements` returns.
    """

    vertices: np.ndarray
    responses: np.ndarray
    jaw_basis: np.ndarray
    jaw_max_angle: float
    jaw_shift_mm: float
    contact_pairs: np.ndarray
    contact_response: np.ndarray
    n_out: int

    @property
    def mesh(self):
        """The kept nodes as a stand-in for the subject's mesh (``vertices`` only)."""
        return self

    def _jaw_terms(self, A: np.ndarray) -> np.ndarray:
        """(F, 4) the jaw's rigid-motion terms for activations ``A`` (F, A)."""
        angle = A[:, action_index("jaw_open")] * self.jaw_max_angle
        shift = self.jaw_shift_mm * (A[:, action_index("jaw_shift_left")]
                                     - A[:, action_index("jaw_shift_right")])
        return _terms(angle, shift, self.jaw_max_angle)

    def displacements(self, A) -> np.ndarray:
        """(F, n_out, 3) displacements (mm) of the output nodes for activations ``A`` (F, A)."""
        from lipgen.subject.motion import Subject
        from lipgen.subject.sources import _wrap

        A = np.asarray(A, dtype=np.float64)
        if A.ndim != 2 or A.shape[1] != len(ACTIONS) or not np.isfinite(A).all():
            raise ValueError(f"activations must be finite with shape (F, {len(ACTIONS)}), got {A.shape}")
        m = len(self.vertices)
        lin = (A @ self.responses.reshape(len(ACTIONS), -1)
               + self._jaw_terms(A) @ self.jaw_basis.reshape(4, -1)).reshape(len(A), m, 3)
        if len(self.contact_pairs):
            lam = Subject._contact_forces(self, lin)  # the subject's own LCP on these nodes
            lin += (lam @ self.contact_response.reshape(len(self.contact_pairs), -1)).reshape(lin.shape)
        X = self.vertices[: self.n_out]
        return _wrap(X, lin[:, : self.n_out]) - X

    # ---- files ----------------------------------------------------------------------------
    def save(self, path: str | os.PathLike) -> None:
        """Write to ``.npz`` (schema-versioned, atomic)."""
        from lipgen._io import save_npz

        save_npz(path, _KIND, _SCHEMA, {
            "vertices": self.vertices, "responses": self.responses, "jaw_basis": self.jaw_basis,
            "jaw_max_angle": np.float64(self.jaw_max_angle), "jaw_shift_mm": np.float64(self.jaw_shift_mm),
            "contact_pairs": self.contact_pairs, "contact_response": self.contact_response,
            "n_out": np.int64(self.n_out), "actions": np.array(ACTIONS)})

    @classmethod
    def load(cls, path: str | os.PathLike) -> NodeMotion:
        """Read a file written by :meth:`save` (``ModelFileError`` if it is of other actions)."""
        from lipgen._io import load_npz
        from lipgen.errors import ModelFileError

        keys = ("vertices", "responses", "jaw_basis", "jaw_max_angle", "jaw_shift_mm", "contact_pairs",
                "contact_response", "n_out", "actions")
        d = load_npz(path, _KIND, _SCHEMA, required=keys)
        if tuple(d["actions"].tolist()) != tuple(ACTIONS):
            raise ModelFileError(f"{path} was written for the actions {tuple(d['actions'].tolist())}, "
                                 f"not {tuple(ACTIONS)}; write it again (lipgen.speech.defaults)")
        return cls(d["vertices"], d["responses"], d["jaw_basis"], float(d["jaw_max_angle"]),
                   float(d["jaw_shift_mm"]), d["contact_pairs"], d["contact_response"], int(d["n_out"]))


def _terms(angle: np.ndarray, shift: np.ndarray, max_angle: float) -> np.ndarray:
    angle = np.asarray(angle, dtype=np.float64)
    return np.stack([np.cos(angle) - 1.0, np.sin(angle), (angle / max_angle) ** 2,
                     np.asarray(shift, dtype=np.float64)], axis=1)


def node_motion(subject, n_out: int) -> NodeMotion:
    """The :class:`NodeMotion` of ``subject`` (a :class:`lipgen.subject.motion.Subject`) on its
    first ``n_out`` nodes (and its contact nodes).

    The jaw basis comes from ``subject.jaw_displacement`` at four openings and shifts (large
    angles, so that the four terms are far from collinear), by the linearity of its solve.
    """
    n_out = int(n_out)
    if not 0 < n_out <= subject.n_nodes:
        raise ValueError(f"n_out must be in [1, {subject.n_nodes}], got {n_out}")
    pairs = np.asarray(subject.contact_pairs if subject.contact_pairs is not None else np.zeros((0, 2)), int)
    extra = np.setdiff1d(np.unique(pairs), np.arange(n_out))
    kept = np.concatenate([np.arange(n_out), extra])
    where = np.full(subject.n_nodes, -1)
    where[kept] = np.arange(len(kept))
    angle = np.array([np.pi / 2, np.pi, np.pi / 3, np.pi / 2])
    shift = np.array([0.0, 0.0, 0.0, 1.0])
    D = subject.jaw_displacement(angle, shift)[:, kept]  # (4, m, 3)
    C = _terms(angle, shift, subject.jaw_max_angle)
    basis = np.linalg.solve(C, D.reshape(4, -1)).reshape(D.shape)
    response = (subject.contact_response[:, kept] if len(pairs)
                else np.zeros((0, len(kept), 3)))
    return NodeMotion(subject.mesh.vertices[kept].copy(), np.ascontiguousarray(subject.responses[:, kept]),
                      basis, float(subject.jaw_max_angle), float(subject.jaw_shift_mm), where[pairs],
                      np.ascontiguousarray(response), n_out)


def build_default_lips():
    """(model, mesh, motion) of the default lips, computed from the code (about half a second):
    ten modes of ``lip_mesh(0)`` from 240 frames of the seed-0 subject's random gestures
    (seed 0, 30 fps), ``lip_mesh(0)``, and the seed-0 subject's :class:`NodeMotion` on it."""
    from lipgen.mesh.procedural import lip_mesh
    from lipgen.modes import ModeModel
    from lipgen.subject.activation import random_activations
    from lipgen.subject.motion import default_subject

    mesh = lip_mesh(0)
    subject = default_subject(seed=0, resolution=1)
    U = subject.displacements(random_activations(240, seed=0, fps=30.0))[:, :mesh.n_nodes]
    model = ModeModel(n_modes=10).fit(U, mesh=mesh)
    return model, mesh, node_motion(subject, mesh.n_nodes)


def save_default_lips(folder: str | os.PathLike = DATA_DIR) -> Path:
    """Write :func:`build_default_lips` to ``folder`` (the package's data folder by default)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for obj, name in zip(build_default_lips(), _FILES, strict=True):
        obj.save(folder / name)
    return folder


@lru_cache(maxsize=1)
def load_default_lips():
    """(model, mesh, motion) of the default lips, read from the shipped files (cached); built by
    :func:`build_default_lips` where the files are missing."""
    from lipgen.mesh.lipmesh import LipMesh
    from lipgen.modes.model import ModeModel

    missing = [name for name in _FILES if not (DATA_DIR / name).is_file()]
    if missing:  # e.g. a build that ships .py files only (the Blender extension's wheel)
        log.info("the default lips' files %s are not in %s: building them (about half a second)",
                 missing, DATA_DIR)
        return build_default_lips()
    return (ModeModel.load(DATA_DIR / _FILES[0]), LipMesh.load(DATA_DIR / _FILES[1]),
            NodeMotion.load(DATA_DIR / _FILES[2]))
