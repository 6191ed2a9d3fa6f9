"""Similarity transforms and the result of a normalisation (shared by the lip-plane and the
head-pose methods of :mod:`lipgen.recon.normalize` and :mod:`lipgen.recon.headpose`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lipgen._validate import as_float_array

__all__ = ["Similarity", "umeyama", "Normalization", "most_neutral_frame"]


@dataclass(frozen=True, eq=False)
class Similarity:
    """``x -> scale * rotation @ x + translation``.

    Attributes
    ----------
    scale : float
    rotation : (3, 3) float, proper (det +1)
    translation : (3,) float
    """

    scale: float
    rotation: np.ndarray
    translation: np.ndarray

    def apply(self, X) -> np.ndarray:
        """Transform points ``X (..., 3)``."""
        X = np.asarray(X, dtype=np.float64)
        return self.scale * X @ self.rotation.T + self.translation

    def inverse(self) -> Similarity:
        """The similarity that undoes this one."""
        Rt = self.rotation.T
        return Similarity(1.0 / self.scale, Rt, -(Rt @ self.translation) / self.scale)


def umeyama(src, dst, with_scale: bool = True) -> Similarity:
    """Least-squares similarity taking ``src`` onto ``dst`` (Umeyama 1991), never a reflection.

    Parameters
    ----------
    src, dst : (k, d) float
        Corresponding points, k >= d (d = 2 or 3 in practice).
    with_scale : bool
        Fit the scale (else it is 1).

    Returns
    -------
    Similarity
        Minimises ``sum |dst - (s R src + t)|^2``.
    """
    src = as_float_array(src, "src", (None, None))
    dst = as_float_array(dst, "dst", src.shape)
    k, d = src.shape
    if k < d:
        raise ValueError(f"umeyama needs at least {d} point pairs for {d}-D points, got {k}")
    ms, md = src.mean(0), dst.mean(0)
    a, b = src - ms, dst - md
    var = (a * a).sum() / k
    if var <= 0:
        raise ValueError("umeyama: the source points all coincide; no rotation or scale is defined")
    U, S, Vt = np.linalg.svd(b.T @ a / k)
    sign = np.ones(d)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        sign[-1] = -1.0
    R = (U * sign) @ Vt
    s = float((S * sign).sum() / var) if with_scale else 1.0
    return Similarity(s, R, md - s * R @ ms)


@dataclass(frozen=True, eq=False)
class Normalization:
    """The result of :func:`lipgen.recon.normalize.normalize_markers`.

    Attributes
    ----------
    markers : (F, P, 3) float
        Markers in the model frame, mm (NaN where not visible).
    rotations : (F, 3, 3) float
        Per-frame lip frames (rows x, y, z), in the data's frame.
    similarity : Similarity
        The one transform from the lip frame onto the model, fitted on ``reference_frame``.
    plane_angle : (F,) float
        Angle between the lip planes, radians (NaN where a frame had too few markers).
    borrowed : (F,) bool
        Frames whose lip frame was taken from the nearest good frame (too few visible markers).
    fit_rms : float
        RMS residual (mm) of the similarity fit on the reference frame.
    reference_frame : int
        The frame the similarity was fitted on.
    method : str
        One of :data:`METHODS`.
    cost : (F,) float or None
        For the pose methods, each frame's residual cost ``yᵀ W y`` (NaN where borrowed).
    outliers : (F, P) bool or None
        For the pose methods, markers left out of the frame's pose fit as mis-measured (see
        ``outlier_ratio`` of :func:`normalize_markers`); they are still in ``markers``.
    """

    markers: np.ndarray
    rotations: np.ndarray
    similarity: Similarity
    plane_angle: np.ndarray
    borrowed: np.ndarray
    fit_rms: float
    reference_frame: int = 0
    method: str = "thesis"
    cost: np.ndarray | None = None
    outliers: np.ndarray | None = None


def most_neutral_frame(local: np.ndarray, vis: np.ndarray, model_markers: np.ndarray, model_nose) -> int:
    """The frame (among those seeing the most markers) whose similarity fit to the rest markers
    leaves the smallest RMS residual."""
    counts = vis.sum(1)
    best, best_rms = -1, np.inf
    for f in np.flatnonzero(counts == counts.max()):
        src, dst = local[f, vis[f]], model_markers[vis[f]]
        if model_nose is not None:
            src, dst = np.vstack([src, np.zeros(3)]), np.vstack([dst, model_nose])
        if len(src) < 3:
            continue
        sim = umeyama(src, dst)
        rms = float(np.sqrt(((sim.apply(src) - dst) ** 2).sum(1).mean()))
        if rms < best_rms:
            best, best_rms = int(f), rms
    if best < 0:
        raise ValueError("no frame has 3 visible markers to fit the similarity to the model")
    return best
