"""Truth-free plausibility of a reconstruction: what can be judged without ground truth.

Two failure modes of NRSfM leave the reprojection error small: depth that inflates (a factor
with many basis shapes explains the image with a stretched z), and depth that jitters from
frame to frame (per-frame ambiguities resolved inconsistently). Real bodies move smoothly and
keep their proportions, so both show in the camera-frame shapes alone:

- ``depth_ratio``: RMS depth spread over RMS in-image spread, over all frames;
- ``roughness``: mean squared second difference in time of the camera-frame shapes, relative
  to their mean squared size (zero for uniform motion, large for jitter).

:func:`plausible` compares them with those of a reference reconstruction (Dai's trace-norm
shapes) to keep or drop a refinement; the truth is never used.
"""

from __future__ import annotations

import numpy as np

__all__ = ["depth_ratio", "roughness", "rotation_roughness", "shape_figures", "plausible",
           "ROUGHNESS_LIMIT", "DEPTH_LIMIT"]


def depth_ratio(shapes: np.ndarray) -> float:
    """RMS depth over RMS image-plane spread of centred camera-frame ``shapes`` (F, 3, P)."""
    c = shapes - shapes.mean(axis=2, keepdims=True)
    xy = float(np.sqrt(np.mean(c[:, :2] ** 2)))
    return float(np.sqrt(np.mean(c[:, 2] ** 2))) / max(xy, 1e-300)


def roughness(shapes: np.ndarray, axis: slice = slice(None)) -> float:
    """Mean squared second time difference of centred camera-frame ``shapes`` (F, 3, P) over their
    mean squared size (0 with fewer than 3 frames); ``axis`` picks coordinates (``slice(2, 3)``:
    depth only)."""
    c = shapes - shapes.mean(axis=2, keepdims=True)
    if c.shape[0] < 3:
        return 0.0
    d2 = c[2:, axis] - 2 * c[1:-1, axis] + c[:-2, axis]
    return float(np.mean(d2**2)) / max(float(np.mean(c**2)), 1e-300)


def rotation_roughness(R: np.ndarray) -> float:
    """Mean squared second time difference of the camera rotations (Frobenius norm per frame).

    Cameras (and bodies turning before them) move smoothly, so rotations that jitter from frame to
    frame - a corrective transform that fits the tracks but not a real motion, or per-frame sign
    flips resolved inconsistently - show as a large value. Compared between reconstructions of one
    sequence only (it grows with the speed of rotation).

    Parameters
    ----------
    R : (F, 3, 3) float
        Object-to-camera rotations in frame order.

    Returns
    -------
    float
        0 with fewer than 3 frames; ``8 (1 - cos a)^2`` (about ``2 a^4``) for uniform rotation by
        ``a`` rad per frame about a fixed axis.
    """
    R = np.asarray(R, dtype=np.float64)
    if R.shape[0] < 3:
        return 0.0
    d2 = R[2:] - 2 * R[1:-1] + R[:-2]
    return float(np.mean(np.sum(d2**2, axis=(1, 2))))


ROUGHNESS_LIMIT = 5.0
"""Largest depth roughness of a plausible refinement, as a multiple of the reference's (see DEPTH_LIMIT)."""

DEPTH_LIMIT = 2.0
"""A refined shape sequence is plausible when its depth roughness is at most ROUGHNESS_LIMIT times,
and its depth ratio at most DEPTH_LIMIT times, those of the reference (Dai's trace-norm shapes,
which reproject exactly and are the least-trace-norm answer). Chosen on the validation set of
:mod:`.validation` (never on drink, jaws or a tester's data): where the rank-K fit blew up
(e3D 1.7-19) its depth roughness was 30-300x and its depth ratio 2-70x the reference's; where it
helped, below 3.5x and 1.5x."""


def shape_figures(R: np.ndarray, object_shapes: np.ndarray) -> dict:
    """``depth_ratio`` and ``depth_roughness`` of object-frame shapes (F, 3, P) seen by rotations R."""
    cam = np.einsum("fij,fjp->fip", R, object_shapes)
    return {"depth_ratio": depth_ratio(cam), "depth_roughness": roughness(cam, slice(2, 3))}


def plausible(candidate: dict, reference: dict) -> bool:
    """Whether ``candidate``'s figures (:func:`shape_figures`) stay within the limits of ``reference``'s."""
    return bool(candidate["depth_roughness"] <= ROUGHNESS_LIMIT * reference["depth_roughness"] + 1e-12
                and candidate["depth_ratio"] <= DEPTH_LIMIT * reference["depth_ratio"] + 1e-12)
