"""Image conditions: how a real camera-mirror recording departs from an ideal pinhole render.

:class:`ImageConditions` is one frozen record of the lens (OpenCV distortion, defocus), the
exposure (shutter time for motion blur, brightness, white balance), the lighting variation, the
mirror (reflectance, tint, front-surface ghost, finite extent) and the sensor (shot and read
noise, Bayer mosaic, JPEG). It is renderer-independent: the renderers read it, and it is stored
in the dataset manifest under ``settings.conditions``. ``ImageConditions()`` (every effect off)
gives exactly the frames of the ideal renderer.

Numbers are in physical units where they exist (mm, seconds as a fraction of the frame interval,
electrons); pixel sizes refer to the full-resolution raw frame.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace

import numpy as np

__all__ = ["ImageConditions", "CODECS", "VIDEO_CODECS"]

CODECS = ("png", "jpeg")
"""How raw frames are stored: lossless PNG, or PNG of the JPEG-decoded frame (``jpeg_quality``)."""
VIDEO_CODECS = ("h264",)
"""Codecs of the optional video of the frames (``video_codec``)."""


def _check_range(name: str, value, lo: float, hi: float) -> float:
    v = float(value)
    if not np.isfinite(v) or not lo <= v <= hi:
        raise ValueError(f"ImageConditions.{name} must be in [{lo}, {hi}], got {value!r}")
    return v


@dataclass(frozen=True)
class ImageConditions:
    """What the lens, the mirror, the light and the sensor do to a frame.

    Parameters
    ----------
    distortion : (5,) float
        OpenCV ``(k1, k2, p1, p2, k3)`` of the camera lens; all zero for an ideal pinhole.
    focus_mm : float
        Distance at which the lens is focused, mm (0: everything sharp).
    aperture_px : float
        Defocus blur diameter of a point at infinity, px; a point at depth z is blurred by a disc
        of diameter ``aperture_px * |z - focus_mm| / z`` (thin lens).
    shutter : float
        Exposure time as a fraction of the frame interval (0: instantaneous, no motion blur).
    blur_samples : int
        Sub-frame instants rendered across the exposure at most (>= 2 when ``shutter`` > 0).
    blur_step_px : float
        Largest step, px, of a mark's image between two rendered instants of the exposure: a frame
        whose marks move ``L`` px while the shutter is open gets ``1 + ceil(L / blur_step_px)``
        instants (at most ``blur_samples``; one when ``L < blur_step_px``).
    exposure : float
        Brightness multiplier of all lights (1: the scene's own light).
    white_balance : (3,) float
        Per-channel gains (R, G, B) of the camera's white balance error.
    light_jitter : float
        Per-dataset random variation of the lights (0: the default lights); directions turn by
        up to ``40 * light_jitter`` degrees and intensities vary by up to ``50 * light_jitter`` %.
    shadows : bool
        The lights cast shadows (pyrender's shadow maps).
    mirror_reflectance : float
        Fraction of the light the mirror returns.
    mirror_tint : (3,) float
        Colour of the mirror's reflection (silver on glass is slightly green).
    ghost : float
        Reflectance of the glass's front surface: a faint second image, offset by the glass.
    glass_mm : float
        Thickness of the mirror's glass (offset of the ghost), mm.
    mirror_extent_mm : (2,) float
        Half width and half height of the mirror, mm (0: infinite). Beyond its edge the camera
        sees the dark room.
    full_well : float
        Electrons at full scale (shot noise); 0 for no shot noise.
    read_noise : float
        Read noise, standard deviation in 8-bit grey levels (linear light, before the tone curve).
    bayer : bool
        The sensor has an RGGB Bayer mosaic, demosaiced by OpenCV.
    codec : str
        ``"png"`` (lossless) or ``"jpeg"`` (the camera compresses; stored decoded).
    jpeg_quality : int
        JPEG quality, 1..100 (with ``codec="jpeg"``).
    texture : float
        Strength of the subject's procedural skin and lip textures (pores, blotches, lip lines;
        skin tone drawn per subject), 0 for plain colours.
    video_codec : str
        ``""`` (no video) or ``"h264"``: the frames are also delivered as one video, ``video.mp4``.
    video_crf : int
        x264's constant rate factor, 0 (lossless) .. 51; 18 is visually lossless.
    head : bool
        Draw a head round the lips: cheeks, chin, nasolabial folds, a nose with nostrils
        (:mod:`lipgen.subject.head`), shaped per subject.
    head_mesh : (4,) int
        Tessellation of the head: the face proxy's rings and border subdivision, the nose's rings
        and sectors (:mod:`lipgen.subject.head`); chosen per preset from the pixel error of the
        mesh against a finer one at the frame's scale.
    mouth : bool
        Draw teeth, tongue and a deep oral cavity (:mod:`lipgen.subject.mouth`).
    ink : float
        0..1: how irregular the ink dots are, in size and edge (:mod:`lipgen.subject.ink`).
    smudge : float
        0..1: how far the ink smudges over the clip (opacity of its halo at the last frame).
    """

    distortion: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    focus_mm: float = 0.0
    aperture_px: float = 0.0
    shutter: float = 0.0
    blur_samples: int = 1
    blur_step_px: float = 1.0
    exposure: float = 1.0
    white_balance: tuple[float, float, float] = (1.0, 1.0, 1.0)
    light_jitter: float = 0.0
    shadows: bool = False
    mirror_reflectance: float = 0.9
    mirror_tint: tuple[float, float, float] = (1.0, 1.0, 1.0)
    ghost: float = 0.0
    glass_mm: float = 0.0
    mirror_extent_mm: tuple[float, float] = (0.0, 0.0)
    full_well: float = 0.0
    read_noise: float = 0.0
    bayer: bool = False
    codec: str = "png"
    jpeg_quality: int = 95
    texture: float = 0.0
    video_codec: str = ""
    video_crf: int = 18
    head: bool = False
    head_mesh: tuple[int, int, int, int] = (28, 4, 36, 64)
    mouth: bool = False
    ink: float = 0.0
    smudge: float = 0.0

    def __post_init__(self) -> None:
        def vec(name, n, lo, hi):
            a = np.asarray(getattr(self, name), dtype=float)
            if a.shape != (n,) or not np.isfinite(a).all() or (a < lo).any() or (a > hi).any():
                raise ValueError(f"ImageConditions.{name} must be {n} numbers in [{lo}, {hi}], got "
                                 f"{getattr(self, name)!r} (shape {a.shape})")
            object.__setattr__(self, name, tuple(float(x) for x in a))

        vec("distortion", 5, -1.0, 1.0)
        vec("white_balance", 3, 0.25, 4.0)
        vec("mirror_tint", 3, 0.0, 1.0)
        vec("mirror_extent_mm", 2, 0.0, 1e4)
        for name, lo, hi in (("focus_mm", 0, 1e5), ("aperture_px", 0, 50), ("shutter", 0, 1),
                             ("exposure", 0.05, 20), ("light_jitter", 0, 1), ("mirror_reflectance", 0.05, 1),
                             ("ghost", 0, 0.5), ("glass_mm", 0, 20), ("full_well", 0, 1e7),
                             ("read_noise", 0, 50), ("texture", 0, 1), ("ink", 0, 1), ("smudge", 0, 1),
                             ("blur_step_px", 0.05, 100)):
            object.__setattr__(self, name, _check_range(name, getattr(self, name), lo, hi))
        if self.aperture_px > 0 and self.focus_mm <= 0:
            raise ValueError(f"ImageConditions.aperture_px = {self.aperture_px} needs focus_mm > 0 "
                             "(the distance the lens is focused at, mm)")
        for name, lo, hi in (("blur_samples", 1, 64), ("jpeg_quality", 1, 100), ("video_crf", 0, 51)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or not lo <= v <= hi:
                raise ValueError(f"ImageConditions.{name} must be a whole number in [{lo}, {hi}], got {v!r}")
            object.__setattr__(self, name, int(v))
        hm = self.head_mesh
        if (not isinstance(hm, tuple | list) or len(hm) != 4
                or not all(isinstance(v, int | np.integer) and not isinstance(v, bool) for v in hm)
                or not (2 <= hm[0] <= 200 and 1 <= hm[1] <= 16 and 4 <= hm[2] <= 200 and 8 <= hm[3] <= 400)):
            raise ValueError("ImageConditions.head_mesh must be 4 whole numbers (rings 2-200, border "
                             f"subdivision 1-16, nose rings 4-200, nose sectors 8-400), got {hm!r}")
        object.__setattr__(self, "head_mesh", tuple(int(v) for v in hm))
        if self.shutter > 0 and self.blur_samples < 2:
            raise ValueError(f"ImageConditions.shutter = {self.shutter} needs blur_samples >= 2 (sub-frame "
                             "instants across the exposure)")
        for name in ("shadows", "bayer", "head", "mouth"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"ImageConditions.{name} must be True or False, got {getattr(self, name)!r}")
        if self.codec not in CODECS:
            raise ValueError(f"ImageConditions.codec must be one of {CODECS}, got {self.codec!r}")
        if self.video_codec not in ("", *VIDEO_CODECS):
            raise ValueError(f"unknown video codec {self.video_codec!r}; choose one of {VIDEO_CODECS} "
                             "(or none)")

    # ---- what is on ---------------------------------------------------------------------------
    @property
    def lens_distortion(self) -> np.ndarray | None:
        """(5,) OpenCV distortion, or None for an ideal pinhole."""
        d = np.array(self.distortion)
        return d if d.any() else None

    @property
    def sub_frame_offsets(self) -> np.ndarray:
        """(s,) instants of the exposure relative to the frame time, in frame intervals."""
        if self.shutter == 0:
            return np.zeros(1)
        return self.shutter * (np.arange(self.blur_samples) / (self.blur_samples - 1) - 0.5)

    def defocus_diameter(self, depth_mm: float) -> float:
        """Blur disc diameter (px) of a point ``depth_mm`` from the camera (thin lens)."""
        if self.aperture_px == 0:
            return 0.0
        return self.aperture_px * abs(depth_mm - self.focus_mm) / depth_mm

    @property
    def is_ideal(self) -> bool:
        """Every effect off (the ideal renderer's frames; a video may still be written)."""
        return replace(self, video_codec="", video_crf=18) == ImageConditions()

    # ---- files --------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """The conditions as a JSON-ready dict (as stored in the manifest)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, d: dict) -> ImageConditions:
        """Conditions from a manifest's dict (written by :meth:`to_dict`)."""
        if not isinstance(d, dict):
            raise TypeError(f"image conditions must be a dict, got {type(d).__name__}")
        known = {f.name for f in fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"unknown image conditions {sorted(unknown)}; known: {sorted(known)}")
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})
