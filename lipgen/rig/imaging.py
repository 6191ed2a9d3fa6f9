"""Forming a raw frame as a real camera-mirror rig does: exposure, lens, mirror and sensor.

A renderer gives ideal view images (pinhole with the lens distortion resampled, one instant).
:class:`FrameFormer` turns the view images of the sub-frame instants of one exposure into the
raw frame under :class:`~lipgen.rig.conditions.ImageConditions`:

1. motion blur: the mean, in linear light, of the instants across the shutter time;
2. defocus: a disc (pillbox) blur whose diameter follows the thin lens at each view's distance;
3. the mirror (virtual view): reflectance and tint, a faint ghost from the glass's front surface
   (the face reflected in a plane ``glass_mm`` nearer the camera) and, beyond the mirror's edge,
   the dark room;
4. the sensor: exposure and white balance gains, shot noise (Poisson, as Gaussian with the
   variance of the electron count) and read noise, the sRGB tone curve, an RGGB Bayer mosaic
   demosaiced by OpenCV, and JPEG compression.

Everything is numpy/OpenCV on arrays, independent of the renderer. The random draws come from
the generator passed in (seeded per frame by the caller).
"""

from __future__ import annotations

import numpy as np

from lipgen._optional import require
from lipgen.rig.camera import MirrorRig
from lipgen.rig.conditions import ImageConditions

__all__ = ["FrameFormer", "srgb_encode", "srgb_decode", "mirror_centre"]

_ROOM = 0.02  # linear radiance of the room seen beyond the mirror's edge


def _decode_curve(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _encode_curve(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)


_DECODE = _decode_curve(np.arange(256) / 255.0).astype(np.float32)
_ENCODE_STEPS = 1 << 16
_ENCODE = np.clip(np.round(255 * _encode_curve(np.arange(_ENCODE_STEPS) / (_ENCODE_STEPS - 1))),
                  0, 255).astype(np.uint8)


def srgb_decode(img: np.ndarray) -> np.ndarray:
    """uint8 sRGB to float32 linear light in [0, 1] (table look-up)."""
    return _DECODE[img]


def srgb_encode(lin: np.ndarray) -> np.ndarray:
    """float linear light to uint8 sRGB (clipped to [0, 1]; table of 65536 linear steps, finer
    than one grey level everywhere)."""
    idx = np.clip(lin * np.float32(_ENCODE_STEPS - 1) + np.float32(0.5), 0, _ENCODE_STEPS - 1)
    return _ENCODE[idx.astype(np.int32)]


def mirror_centre(rig: MirrorRig, target=(0.0, 5.0, 0.0)) -> np.ndarray:
    """(3,) point of the mirror plane where the virtual camera's line of sight to ``target`` crosses it."""
    c = rig.virtual_view.center
    t = np.asarray(target, float)
    n, d = rig.mirror_normal, rig.mirror_offset
    s = (d - n @ c) / (n @ (t - c))
    return c + s * (t - c)


def _mirror_axes(rig: MirrorRig) -> tuple[np.ndarray, np.ndarray]:
    n = rig.mirror_normal
    ey = np.array([0.0, 1.0, 0.0]) - n[1] * n
    ey /= np.linalg.norm(ey)
    return np.cross(ey, n), ey


def on_mirror(rig: MirrorRig, extent, points) -> np.ndarray:
    """(...,) bool: the virtual camera's lines of sight to world ``points`` (...,3) cross the mirror
    plane inside its rectangle of half sizes ``extent`` (mm); all True for an infinite mirror."""
    P = np.asarray(points, float)
    if not np.asarray(extent).any():
        return np.ones(P.shape[:-1], bool)
    c = rig.virtual_view.center
    n, d = rig.mirror_normal, rig.mirror_offset
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (d - n @ c) / ((P - c) @ n)
    X = c + s[..., None] * (P - c)
    ex, ey = _mirror_axes(rig)
    q = X - mirror_centre(rig)
    return (np.abs(q @ ex) <= extent[0]) & (np.abs(q @ ey) <= extent[1]) & (s > 0)


class FrameFormer:
    """Forms raw frames of one rig under fixed :class:`ImageConditions`.

    Parameters
    ----------
    rig : MirrorRig
        With the lens distortion of the conditions (``rig.camera.dist``).
    conditions : ImageConditions
    exposure : float
        Brightness gain of this dataset (``conditions.exposure`` times its per-dataset variation).
    white_balance : (3,) float
        Channel gains of this dataset.
    target : (3,) float
        The point the lens is focused around (the mouth), world mm: sets each view's distance.
    """

    def __init__(self, rig: MirrorRig, conditions: ImageConditions, exposure: float | None = None,
                 white_balance=None, target=(0.0, 5.0, 0.0)) -> None:
        self.cv2 = require("cv2", "forming camera frames (defocus, Bayer demosaicing, JPEG)")
        self.rig, self.c = rig, conditions
        self.exposure = conditions.exposure if exposure is None else float(exposure)
        self.wb = np.asarray(conditions.white_balance if white_balance is None else white_balance, np.float32)
        target = np.asarray(target, float)
        self.kernels = [self._disc(conditions.defocus_diameter(float(np.linalg.norm(cam.center - target))))
                        for cam in rig.views]
        vv = rig.virtual_view
        g = conditions.glass_mm
        self.ghost_shift = (vv.project(target - 2 * g * rig.mirror_normal) - vv.project(target)
                            if conditions.ghost > 0 else np.zeros(2))
        uu, vq = np.meshgrid(np.arange(vv.width, dtype=float), np.arange(vv.height, dtype=float))
        o, dirs = vv.rays(np.stack([uu, vq], -1))
        self.mirror_mask = on_mirror(rig, conditions.mirror_extent_mm, o + 500.0 * dirs)[..., None]
        self.tint = (conditions.mirror_reflectance * np.asarray(conditions.mirror_tint)).astype(np.float32)

    def _disc(self, diameter: float) -> np.ndarray | None:
        if diameter < 0.5:
            return None
        r = diameter / 2
        n = int(np.ceil(r))
        # each tap weighted by the area of the disc over its pixel (4x4 supersampled)
        s = (np.arange(4) + 0.5) / 4 - 0.5
        y, x = np.mgrid[-n:n + 1, -n:n + 1].astype(float)
        inside = ((x[..., None, None] + s[:, None]) ** 2 + (y[..., None, None] + s[None, :]) ** 2) <= r * r
        k = inside.mean(axis=(2, 3)).astype(np.float32)
        return k / k.sum()

    def views(self, instants: list) -> list[np.ndarray]:
        """(virtual, real) linear float view images from the renders of the sub-frame instants.

        ``instants`` is a list (one per instant) of (virtual, real) uint8 sRGB view images.
        """
        out = []
        for v in range(2):
            if len(instants) == 1:  # the mean of one image is that image, bit for bit
                lin = srgb_decode(instants[0][v])
            else:
                lin = np.mean([srgb_decode(inst[v]) for inst in instants], axis=0)
            if self.kernels[v] is not None:
                lin = self.cv2.filter2D(lin, -1, self.kernels[v], borderType=self.cv2.BORDER_REPLICATE)
            out.append(lin)
        virt = out[0]
        mirrored = virt * self.tint
        if self.c.ghost > 0:
            M = np.float32([[1, 0, self.ghost_shift[0]], [0, 1, self.ghost_shift[1]]])
            ghost = self.cv2.warpAffine(virt, M, (virt.shape[1], virt.shape[0]),
                                        borderMode=self.cv2.BORDER_REPLICATE)
            mirrored = mirrored * (1 - self.c.ghost) ** 2 + self.c.ghost * ghost
        out[0] = np.where(self.mirror_mask, mirrored, np.float32(_ROOM))
        return out

    def sensor(self, lin: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """(H, W, 3) uint8 frame from the linear light ``lin`` on the sensor."""
        c, cv2 = self.c, self.cv2
        x = lin * (np.float32(self.exposure) * self.wb)
        if c.full_well > 0 or c.read_noise > 0:
            # shot (variance = electrons) and read noise, independent Gaussians: one draw. In place,
            # the same float32 operations as var = read + clip(x) / full_well; x += sqrt(var) * z
            read = np.float32((c.read_noise / 255.0) ** 2)
            if c.full_well > 0:
                sd = np.clip(x, 0, 1)
                sd *= np.float32(1.0 / c.full_well)
                sd += read
                np.sqrt(sd, out=sd)
            else:
                sd = np.sqrt(read)
            z = rng.standard_normal(x.shape, dtype=np.float32)
            z *= sd
            x += z
        img = srgb_encode(x)
        if c.bayer:
            mosaic = np.empty(img.shape[:2], np.uint8)  # RGGB
            mosaic[0::2, 0::2] = img[0::2, 0::2, 0]
            mosaic[0::2, 1::2] = img[0::2, 1::2, 1]
            mosaic[1::2, 0::2] = img[1::2, 0::2, 1]
            mosaic[1::2, 1::2] = img[1::2, 1::2, 2]
            # OpenCV names Bayer patterns by the second row: RGGB is its BayerBG (to BGR), so BayerBG2RGB
            # would swap; BayerBG2BGR then reversed gives RGB
            img = np.ascontiguousarray(cv2.cvtColor(mosaic, cv2.COLOR_BayerBG2BGR)[..., ::-1])
        if c.codec == "jpeg":
            ok, buf = cv2.imencode(".jpg", img[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, c.jpeg_quality])
            img = np.ascontiguousarray(cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1])
        return img

    def form(self, instants: list, rng: np.random.Generator) -> np.ndarray:
        """The raw (H, W, 3) uint8 frame from the (virtual, real) view renders of each instant."""
        virt, real = self.views(instants)
        return self.sensor(self.rig.compose(virt, real), rng)
