"""A held-out validation set for NRSfM: synthetic human bodies filmed orthographically.

Every sequence is a kinematic skeleton with human proportions (pelvis, spine, head, two arms,
two legs; bone lengths jittered per seed), markers on the body surface (40-75 of them), and
one of four kinds of motion - walking, reaching down and picking up, dancing, stretching - drawn
with random amplitudes, speeds and phases. The body turns about the vertical while the
(orthographic) camera nods, at a rate drawn per sequence (0.5-6 degrees per frame), so some
sequences see little rotation (the hard case) and some a lot. Sequences are generated on the fly
from their seed: nothing is stored, and methods are never tuned on them (they are only scored).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._rotation import expm_so3

__all__ = ["HumanSequence", "human_sequence", "film_orthographic", "validation_set", "MOTIONS"]

MOTIONS = ("walk", "pickup", "dance", "stretch")
"""The kinds of motion of the validation bodies (sequence ``seed`` gets ``MOTIONS[seed % 4]``)."""

# joint: (parent, rest direction (y up), length in units of the body height)
_BONES = {
    "pelvis": (None, (0, 0, 0), 0.0), "spine": ("pelvis", (0, 1, 0), 0.12),
    "chest": ("spine", (0, 1, 0), 0.15), "neck": ("chest", (0, 1, 0), 0.08),
    "head": ("neck", (0, 1, 0), 0.12),
    "l_shoulder": ("chest", (1, 0.15, 0), 0.10), "l_elbow": ("l_shoulder", (0, -1, 0), 0.17),
    "l_wrist": ("l_elbow", (0, -1, 0), 0.15), "l_hand": ("l_wrist", (0, -1, 0), 0.07),
    "r_shoulder": ("chest", (-1, 0.15, 0), 0.10), "r_elbow": ("r_shoulder", (0, -1, 0), 0.17),
    "r_wrist": ("r_elbow", (0, -1, 0), 0.15), "r_hand": ("r_wrist", (0, -1, 0), 0.07),
    "l_hip": ("pelvis", (1, -0.3, 0), 0.09), "l_knee": ("l_hip", (0, -1, 0), 0.24),
    "l_ankle": ("l_knee", (0, -1, 0), 0.24), "l_toe": ("l_ankle", (0, -0.3, 1), 0.08),
    "r_hip": ("pelvis", (-1, -0.3, 0), 0.09), "r_knee": ("r_hip", (0, -1, 0), 0.24),
    "r_ankle": ("r_knee", (0, -1, 0), 0.24), "r_toe": ("r_ankle", (0, -0.3, 1), 0.08),
}
_NAMES = list(_BONES)
_RADIUS = {"head": 0.06, "chest": 0.09, "spine": 0.08, "pelvis": 0.08}   # body surface offsets

# per motion: joint -> amplitude (rad) of its swing about x (forward/back), z (sideways), y (twist)
_AMPLITUDE = {
    "walk": {"l_hip": (0.5, 0.05, 0.05), "r_hip": (0.5, 0.05, 0.05), "l_knee": (0.6, 0, 0),
             "r_knee": (0.6, 0, 0), "l_shoulder": (0.4, 0.05, 0), "r_shoulder": (0.4, 0.05, 0),
             "l_elbow": (0.3, 0, 0), "r_elbow": (0.3, 0, 0), "spine": (0.05, 0.03, 0.1)},
    "pickup": {"spine": (0.7, 0.1, 0.1), "chest": (0.4, 0.05, 0.1), "l_hip": (0.6, 0, 0),
               "r_hip": (0.6, 0, 0), "l_knee": (0.8, 0, 0), "r_knee": (0.8, 0, 0),
               "r_shoulder": (0.9, 0.2, 0.1), "r_elbow": (0.6, 0, 0), "neck": (0.3, 0, 0)},
    "dance": {name: (0.5, 0.4, 0.3) for name in ("spine", "chest", "l_shoulder", "r_shoulder", "l_elbow",
                                                 "r_elbow", "l_hip", "r_hip", "l_knee", "r_knee", "neck")},
    "stretch": {"l_shoulder": (0.3, 1.3, 0.1), "r_shoulder": (0.3, 1.3, 0.1), "l_elbow": (0.5, 0, 0),
                "r_elbow": (0.5, 0, 0), "spine": (0.2, 0.4, 0.2), "chest": (0.1, 0.3, 0.1)},
}


@dataclass(frozen=True)
class HumanSequence:
    """One validation sequence: tracks ``W`` (2F, P), truth ``S`` (3F, P) camera frame (centred),
    rotations ``R`` (F, 3, 3), and how it was made."""

    name: str
    W: np.ndarray
    S: np.ndarray
    R: np.ndarray
    motion: str
    degrees_per_frame: float
    seed: int


def _axis_angle_rows(angles: np.ndarray) -> np.ndarray:
    return expm_so3(angles)


def human_sequence(seed: int, n_frames: int = 300, motion: str | None = None) -> HumanSequence:
    """A synthetic human body in motion, filmed orthographically (see the module docstring).

    Parameters
    ----------
    seed : int
        Everything random (proportions, markers, motion, camera) follows from it.
    n_frames : int
    motion : str, optional
        One of :data:`MOTIONS`; by default ``MOTIONS[seed % 4]``.
    """
    if motion is None:
        motion = MOTIONS[seed % len(MOTIONS)]
    if motion not in MOTIONS:
        raise ValueError(f"motion must be one of {MOTIONS}, got {motion!r}")
    if n_frames < 3:
        raise ValueError(f"n_frames must be at least 3, got {n_frames}")
    rng = np.random.default_rng(seed)
    nb = len(_NAMES)
    length = np.array([_BONES[n][2] for n in _NAMES]) * rng.uniform(0.9, 1.1, nb) * 1700.0   # mm
    direction = np.array([_BONES[n][1] for n in _NAMES], float)
    direction[1:] /= np.linalg.norm(direction[1:], axis=1, keepdims=True)
    parent = [None if _BONES[n][0] is None else _NAMES.index(_BONES[n][0]) for n in _NAMES]
    # joint motion: a few harmonics per joint and axis, a motion-specific amplitude, small noise
    t = np.arange(n_frames) / 30.0                                         # seconds at 30 Hz
    base = rng.uniform(0.3, 1.0)                                           # Hz of the main rhythm
    amp = np.zeros((nb, 3))
    for name, a in _AMPLITUDE[motion].items():
        amp[_NAMES.index(name)] = a
    amp = amp * rng.uniform(0.6, 1.3, (nb, 3)) + rng.uniform(0.0, 0.05, (nb, 3))
    phase = rng.uniform(0, 2 * np.pi, (nb, 3))
    mirror = np.array([np.pi if n.startswith("r_") and motion == "walk" else 0.0 for n in _NAMES])
    angles = amp * np.sin(2 * np.pi * base * t[:, None, None] + phase + mirror[:, None])
    angles += 0.3 * amp * np.sin(2 * np.pi * 2.3 * base * t[:, None, None] + 2 * phase)
    local = _axis_angle_rows(angles[..., [0, 2, 1]])                       # (F, nb, 3, 3)
    frames = np.zeros((n_frames, nb, 3, 3))
    pos = np.zeros((n_frames, nb, 3))
    for b in range(nb):
        if parent[b] is None:
            frames[:, b] = local[:, b]
        else:
            p = parent[b]
            frames[:, b] = frames[:, p] @ local[:, b]
            pos[:, b] = pos[:, p] + length[b] * (frames[:, p] @ direction[b])
    # markers: 40-75 on the bones (between joint and parent) and off the axis by a body radius
    n_markers = int(rng.integers(40, 76))
    owner = np.concatenate([np.arange(1, nb), rng.integers(1, nb, n_markers - (nb - 1))])
    along = rng.uniform(0.2, 1.0, n_markers)
    radius = np.array([_RADIUS.get(_NAMES[b], 0.04) for b in owner]) * 1700.0
    radius = radius * rng.uniform(0.5, 1.0, n_markers)
    off = rng.standard_normal((n_markers, 3))
    off /= np.linalg.norm(off, axis=1, keepdims=True)
    pts = []
    for m, b in enumerate(owner):
        p = parent[b]
        seg = pos[:, p] + along[m] * (pos[:, b] - pos[:, p])
        pts.append(seg + radius[m] * (frames[:, p] @ off[m]))
    X = np.stack(pts, axis=1)                                              # (F, P, 3) world, y up
    W, shapes, R, degrees = film_orthographic(X, rng, t)
    return HumanSequence(name=f"human-{motion}-{seed}", W=W, S=shapes,
                         R=R, motion=motion, degrees_per_frame=degrees, seed=seed)


def film_orthographic(X: np.ndarray, rng: np.random.Generator, t: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Film world points orthographically as the validation bodies are filmed: the body turns about
    the vertical at a rate drawn from ``rng`` (0.5-6 degrees per frame) while the camera nods a
    little, and each frame's image is shifted at random.

    Parameters
    ----------
    X : (F, P, 3) float
        World points, y up.
    rng : numpy Generator
        Draws, in order: the rate, the start angle, the nod's offset and frequency, the shifts.
    t : (F,) float
        Frame times in seconds (the nod's clock).

    Returns
    -------
    W : (2F, P) float
        Tracks (rows u1, v1, u2, ...).
    S : (3F, P) float
        The truth in the camera frame, each frame centred.
    R : (F, 3, 3) float
        Camera rotations.
    degrees : float
        The turn per frame.
    """
    F, P = X.shape[:2]
    degrees = float(rng.uniform(0.5, 6.0))
    yaw = np.radians(degrees) * np.arange(F) + rng.uniform(0, 2 * np.pi)
    pitch = rng.uniform(-0.3, 0.3) + 0.15 * np.sin(2 * np.pi * rng.uniform(0.05, 0.3) * t)
    zeros = np.zeros(F)
    flip = np.diag([1.0, -1.0, -1.0])        # y up (world) to y down (image), camera looking along +z
    R = flip @ expm_so3(np.stack([pitch, zeros, zeros], -1)) @ expm_so3(np.stack([zeros, yaw, zeros], -1))
    shapes = np.einsum("fij,fpj->fip", R, X)
    shapes -= shapes.mean(axis=2, keepdims=True)
    W = (shapes[:, :2] + rng.uniform(-50, 50, (F, 2, 1))).reshape(2 * F, P)
    return W, shapes.reshape(3 * F, P), R, degrees


def validation_set(seeds=range(100, 108), n_frames: int = 300) -> list[HumanSequence]:
    """The held-out sequences: :func:`human_sequence` for each seed (two of each motion by default)."""
    return [human_sequence(int(s), n_frames) for s in seeds]
