"""Rotation helpers shared by the stages: cross-product matrices, Rodrigues and its inverse.

A private top-level module (like :mod:`lipgen._threads`), so that any stage may import it
without breaking the import contract (``recon.headpose`` and ``nrsfm`` both use it).
"""

from __future__ import annotations

import numpy as np

__all__ = ["skew", "rotation_matrix", "rotation_vector"]


def skew(x) -> np.ndarray:
    """Cross-product matrices ``[x]_x`` (``[x]_x y = x × y``).

    Parameters
    ----------
    x : (..., 3) array_like

    Returns
    -------
    (..., 3, 3) float
    """
    x = np.asarray(x, dtype=np.float64)
    Z = np.zeros(x.shape[:-1] + (3, 3))
    Z[..., 0, 1], Z[..., 0, 2] = -x[..., 2], x[..., 1]
    Z[..., 1, 0], Z[..., 1, 2] = x[..., 2], -x[..., 0]
    Z[..., 2, 0], Z[..., 2, 1] = -x[..., 1], x[..., 0]
    return Z


def rotation_matrix(w) -> np.ndarray:
    """Rodrigues: rotations ``exp([w]_x)`` of rotation vectors.

    Parameters
    ----------
    w : (..., 3) array_like
        Axis times angle (radians).

    Returns
    -------
    (..., 3, 3) float
        Rotation matrices (a Taylor expansion below 1e-8 rad).
    """
    w = np.asarray(w, dtype=np.float64)
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    K = skew(w)
    small = theta < 1e-8
    th = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta**2 / 6, np.sin(th) / th)
    b = np.where(small, 0.5 - theta**2 / 24, (1 - np.cos(th)) / th**2)
    return np.eye(3) + a * K + b * (K @ K)


def rotation_vector(R) -> np.ndarray:
    """The inverse of :func:`rotation_matrix` for angles below pi.

    Parameters
    ----------
    R : (..., 3, 3) array_like
        Rotation matrices.

    Returns
    -------
    (..., 3) float
        Rotation vectors (radians); the angle from ``atan2(|vee|, cos)``, accurate at small and
        large angles alike.
    """
    R = np.asarray(R, dtype=np.float64)
    vee = 0.5 * np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0],
                          R[..., 1, 0] - R[..., 0, 1]], axis=-1)
    s = np.linalg.norm(vee, axis=-1, keepdims=True)
    cos = 0.5 * (np.trace(R, axis1=-2, axis2=-1)[..., None] - 1.0)
    angle = np.arctan2(s, cos)
    return vee * np.where(s > 1e-12, angle / np.maximum(s, 1e-300), 1.0)
