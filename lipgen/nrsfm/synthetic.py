"""Synthetic NRSfM sequences with ground truth, for tests, benchmarks and validation.

- :func:`low_rank_sequence`: exactly K basis shapes (a dominant mean shape plus deformation
  modes) seen by orthographic cameras in random or smoothly turning orientations.
- :func:`articulated_sequence`: a random kinematic tree with smooth joint motion filmed by an
  orbiting camera (about 5 degrees per frame, as in the CMU-derived benchmark sequences). It is
  not low-rank; it stands in for motion-capture sequences when choosing method settings.
"""

from __future__ import annotations

import numpy as np

from lipgen.nrsfm._rotation import expm_so3

__all__ = ["random_rotations", "low_rank_sequence", "articulated_sequence"]


def random_rotations(n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` rotations drawn uniformly (unit quaternions), shape ``(n, 3, 3)``."""
    q = rng.standard_normal((n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], axis=1)


def _tracks(shapes: np.ndarray, translation: np.ndarray) -> np.ndarray:
    F, _, P = shapes.shape
    return (shapes[:, :2] + translation[:, :, None]).reshape(2 * F, P)


def low_rank_sequence(n_frames: int, n_points: int, k: int, rng: np.random.Generator,
                      deformation: float = 0.3, smooth: bool = False, translation: float = 2.0):
    """Tracks of an exactly rank-K shape sequence under orthography.

    Shapes are ``B_1 + sum_{i>1} c_fi B_i`` (Gaussian basis, deformation weights of size
    ``deformation``), turned by random rotations (or a smooth turn, ``smooth=True``) and shifted
    by a random image translation.

    Returns
    -------
    W : (2F, P) float
        Tracks, rows u1, v1, u2, v2, ...
    S : (3F, P) float
        Camera-frame shapes, centred, rows x1, y1, z1, ...
    R : (F, 3, 3) float
        The rotations.
    """
    basis = rng.standard_normal((k, 3, n_points))
    basis -= basis.mean(axis=2, keepdims=True)
    weights = np.ones((n_frames, k))
    if k > 1:
        if smooth:
            t = np.linspace(0.0, 1.0, n_frames)[:, None]
            freq = rng.uniform(0.5, 3.0, (1, k - 1))
            phase = rng.uniform(0.0, 2 * np.pi, (1, k - 1))
            weights[:, 1:] = deformation * np.sin(2 * np.pi * freq * t + phase)
        else:
            weights[:, 1:] = deformation * rng.standard_normal((n_frames, k - 1))
    if smooth:
        a = np.linspace(0.0, rng.uniform(1.0, 3.0), n_frames)
        R = expm_so3(np.stack([0.3 * np.sin(2 * a), a, 0.2 * np.cos(a)], axis=-1))
    else:
        R = random_rotations(n_frames, rng)
    shapes = R @ np.einsum("fk,kip->fip", weights, basis)
    W = _tracks(shapes, translation * rng.standard_normal((n_frames, 2)))
    return W, shapes.reshape(3 * n_frames, n_points), R


def articulated_sequence(n_frames: int, rng: np.random.Generator, n_bones: int = 12,
                         markers_per_bone: int = 3, n_active: int = 2, degrees_per_frame: float = 5.0):
    """Tracks of a moving kinematic tree (mocap-like, not low-rank) filmed by an orbiting camera.

    Most joints move a little (up to 0.04 rad per harmonic); ``n_active`` joints move a lot (up
    to 0.5 rad). The camera turns about the vertical by ``degrees_per_frame`` and nods gently.

    Returns
    -------
    W : (2F, P) float
    S : (3F, P) float
        Camera-frame shapes, centred.
    R : (F, 3, 3) float
        World-to-camera rotations.
    """
    parent = [-1] + [int(rng.integers(0, i)) for i in range(1, n_bones)]
    length = rng.uniform(0.5, 1.5, n_bones)
    axis = rng.standard_normal((n_bones, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    t = np.arange(n_frames) / n_frames
    harmonics = np.arange(1, 4)
    amp = rng.uniform(0.0, 0.04, (n_bones, 3, 3)) / harmonics
    active = rng.choice(n_bones, size=n_active, replace=False)
    amp[active] = rng.uniform(0.1, 0.5, (n_active, 3, 3)) / harmonics
    freq = rng.uniform(0.5, 3.0, (n_bones, 3, 3)) * harmonics
    phase = rng.uniform(0.0, 2 * np.pi, (n_bones, 3, 3))
    angles = (amp * np.sin(2 * np.pi * freq * t[:, None, None, None] + phase)).sum(-1)
    local = expm_so3(angles)                                   # (F, bones, 3, 3)
    offsets = 0.15 * rng.standard_normal((n_bones, markers_per_bone, 3))
    along = rng.uniform(0.1, 1.0, (n_bones, markers_per_bone))
    frames = np.zeros((n_frames, n_bones, 3, 3))
    start = np.zeros((n_frames, n_bones, 3))
    end = np.zeros((n_frames, n_bones, 3))
    points = []
    for b in range(n_bones):
        if parent[b] < 0:
            frames[:, b] = local[:, b]
        else:
            frames[:, b] = frames[:, parent[b]] @ local[:, b]
            start[:, b] = end[:, parent[b]]
        end[:, b] = start[:, b] + length[b] * (frames[:, b] @ axis[b])
        marker = along[b][:, None] * length[b] * axis[b] + offsets[b]
        points.append(start[:, b, None] + np.einsum("fij,mj->fmi", frames[:, b], marker))
    X = np.concatenate(points, axis=1)                         # (F, P, 3) world
    yaw = np.radians(degrees_per_frame) * np.arange(n_frames) + rng.uniform(0, 2 * np.pi)
    pitch = 0.3 * np.sin(2 * np.pi * rng.uniform(0.3, 1.5) * t)
    zeros = np.zeros(n_frames)
    R = expm_so3(np.stack([pitch, zeros, zeros], -1)) @ expm_so3(np.stack([zeros, yaw, zeros], -1))
    shapes = np.einsum("fij,fpj->fip", R, X)
    shapes -= shapes.mean(axis=2, keepdims=True)
    W = _tracks(shapes, np.zeros((n_frames, 2)))
    return W, shapes.reshape(3 * n_frames, -1), R
