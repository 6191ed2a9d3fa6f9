"""Lens distortion for renderers that draw pinhole images only: render wider, then resample.

OpenGL (pyrender) and Cycles' perspective camera draw straight lines straight. A camera with
radial and tangential distortion (:class:`~lipgen.rig.pinhole.PinholeCamera` ``dist``) is drawn
as a pinhole image of the same ``K``, shifted and enlarged to hold every ray the distorted image
sees (a :class:`PinholeWindow`), then resampled at the undistorted position of each output pixel:
bilinearly for colour, by the nearest pixel for depth and labels (which must not blend).
"""

from __future__ import annotations

import numpy as np

from lipgen._optional import require
from lipgen.rig.pinhole import PinholeCamera

__all__ = ["PinholeWindow"]


class PinholeWindow:
    """The pinhole image a camera's (distorted) image is resampled from.

    Parameters
    ----------
    cam : PinholeCamera

    Attributes
    ----------
    cam : PinholeCamera
    offset : (2,) float
        Position, in ``cam``'s pixels, of the window's pixel (0, 0); (0, 0) without distortion.
    size : tuple of int
        ``(width, height)`` of the pinhole image to render; ``cam``'s own size without distortion.
    map : (h, w, 2) float32 or None
        For each output pixel, where it lies in the window (x, y); None without distortion.
    nearest : (h, w) int64 or None
        For each output pixel, the flat index of the window pixel nearest to it; None without
        distortion.
    """

    def __init__(self, cam: PinholeCamera) -> None:
        if not isinstance(cam, PinholeCamera):
            raise TypeError(f"cam must be a PinholeCamera, got {type(cam).__name__}")
        self.cam = cam
        self.offset = np.zeros(2)
        self.size = (cam.width, cam.height)
        self.map = self.nearest = None
        if cam.dist is None:
            return
        K = cam.K
        uu, vv = np.meshgrid(np.arange(cam.width, dtype=float), np.arange(cam.height, dtype=float))
        src = cam.normalized(np.stack([uu, vv], -1)) * np.diag(K)[:2] + K[:2, 2]
        lo, hi = np.floor(src.min(axis=(0, 1))) - 2, np.ceil(src.max(axis=(0, 1))) + 2
        w, h = int(hi[0] - lo[0]) + 1, int(hi[1] - lo[1]) + 1
        s = src - lo
        self.cv2 = require("cv2", "rendering a camera with lens distortion")
        self.offset, self.size = lo, (w, h)
        self.map = s.astype(np.float32)  # bilinear resampling by OpenCV's remap (1/32 px weights)
        self.nearest = np.round(s[..., 1]).astype(np.int64) * w + np.round(s[..., 0]).astype(np.int64)

    def resample(self, image: np.ndarray) -> np.ndarray:
        """``(h, w[, c])`` image of the camera from the ``(H, W[, c])`` window image, bilinear
        (edges replicated); the image itself without distortion."""
        if self.map is None:
            return image
        cv2 = self.cv2
        return cv2.remap(image, self.map, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)

    def resample_nearest(self, values: np.ndarray) -> np.ndarray:
        """``(h, w, ...)`` values of the camera from the ``(H, W, ...)`` window's, each the nearest
        window pixel's (for depth and labels); the values themselves without distortion."""
        if self.nearest is None:
            return values
        return values.reshape(-1, *values.shape[2:])[self.nearest]
