"""Speech for a rig: viseme scripts performed by lipgen's synthetic subject.

:mod:`lipgen.subject.motion` animates a *performer* (the synthetic subject: muscle-like actions, a jaw
hinge, lip contact) from a viseme script. Its mesh is LipGen's procedural lips, and the
procedural meshes are nested (node i of a resolution is node i of every finer one), so the
performer's displacements apply node for node to a rig built on ``lip_mesh(r)``. A rig with
modes then follows the performance through its sliders: the frame's displacement projected on
the modes (:meth:`ModeBasis.project`).
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from functools import lru_cache

import numpy as np

__all__ = ["lips_resolution", "performer", "speech_displacements", "gesture_displacements"]

_SUBJECTS: OrderedDict[int, object] = OrderedDict()
_LOCK = threading.Lock()


@lru_cache(maxsize=8)
def _topology(resolution: int) -> tuple[int, str]:
    from lipgen.mesh.procedural import lip_mesh

    m = lip_mesh(resolution)
    return m.n_nodes, m.topology_id


def lips_resolution(n_nodes: int, topology_id: str, max_resolution: int = 4) -> int | None:
    """The resolution r with ``lip_mesh(r)`` of this topology, or None if it is another mesh."""
    for r in range(max_resolution + 1):
        n, topo = _topology(r)
        if n == n_nodes and topo == topology_id:
            return r
        if n > n_nodes:
            return None
    return None


def performer(resolution: int, seed: int = 0):
    """The synthetic subject on ``lip_mesh(max(resolution, 1))`` (cached in memory, 2 kept)."""
    from lipgen.subject.motion import default_subject

    res = max(int(resolution), 1)
    key = res * 1000 + int(seed)
    with _LOCK:
        if key in _SUBJECTS:
            _SUBJECTS.move_to_end(key)
            return _SUBJECTS[key]
    subject = default_subject(seed=seed, resolution=res)
    with _LOCK:
        _SUBJECTS[key] = subject
        while len(_SUBJECTS) > 2:
            _SUBJECTS.popitem(last=False)
    return subject


def _on_lips(resolution: int, U: np.ndarray) -> np.ndarray:
    n, _ = _topology(resolution)
    return U[:, :n]  # nested meshes: the first n nodes of the performer are the rig's nodes


def speech_displacements(script: str, fps: float, resolution: int, coarticulation: float = 0.2,
                         seed: int = 0) -> np.ndarray:
    """(F, n, 3) displacements (mm, model frame) of ``lip_mesh(resolution)`` speaking ``script``.

    ``script`` is a viseme script as :func:`lipgen.subject.activation.viseme_activations` reads it, e.g.
    ``"AA:0.3 EE:0.2 OO M:0.15 F REST:0.4"``; one row per frame at ``fps``.
    """
    from lipgen.subject.activation import viseme_activations

    A = viseme_activations(script, fps=fps, coarticulation=coarticulation)
    return _on_lips(resolution, performer(resolution, seed).displacements(A))


def gesture_displacements(resolution: int, n_frames: int = 240, seed: int = 0,
                          fps: float = 30.0) -> np.ndarray:
    """(F, n, 3) displacements of smooth random gestures of every action: training shapes for
    modes that can follow speech."""
    from lipgen.subject.activation import random_activations

    A = random_activations(n_frames, seed=seed, fps=fps)
    return _on_lips(resolution, performer(resolution).displacements(A))
