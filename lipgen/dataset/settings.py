"""The settings that determine a synthetic dataset's bytes (:class:`GenerateSettings`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

import numpy as np

from lipgen.rig.conditions import ImageConditions

__all__ = ["GenerateSettings", "PRESET_CALIB_FRAMES", "PRESET_LENS_FRAMES", "MAX_WIDTH"]

MAX_WIDTH = 8192
"""The widest image ``lipgen generate`` renders, pixels (OpenGL's framebuffer limit, with room)."""
PRESET_CALIB_FRAMES = 40
"""Calibration frames of a preset with a distorted lens (``default``, ``hard``) ..."""
PRESET_LENS_FRAMES = 30
"""... and how many of them are lens frames (:attr:`GenerateSettings.lens_frames`)."""


@dataclass(frozen=True)
class GenerateSettings:
    """Everything that determines a dataset's bytes (with the lipgen version)."""

    frames: int = 150
    seed: int = 0
    script: str | None = None
    """Viseme script (repeated to fill the frames); smooth random activations if None."""
    size: tuple[int, int] = (640, 480)
    fps: float = 30.0
    subject_resolution: int = 1
    head_rotation_deg: float = 4.0
    head_translation_mm: float = 4.0
    noise: float = 1.0
    """Sensor noise, standard deviation in 8-bit grey levels."""
    dot_diameter: float = 2.0
    calib_frames: int = 10
    lens_frames: int = 0
    """How many of the calibration frames (the last ones) are lens frames: a large dense board
    (:data:`lipgen.rig.target.LENS_BOARD`) filling the direct or the mirror view in turn, so that the
    calibration recovers the lens's tangential terms (:func:`lipgen.rig.target.lens_poses`). The
    presets with a distorted lens have 40 calibration frames, 30 of them lens frames, unless
    ``calib_frames`` or ``lens_frames`` is given."""
    board: tuple[int, int, float] = (9, 6, 8.0)
    """Chessboard inner corners (cols, rows) and square size, mm."""
    png_compress_level: int = 1
    depth: bool = False
    """Also write each raw frame's depth (``depth/NNNNNN.npz``: view-camera z in mm, NaN off the face)."""
    masks: bool = False
    """Also write each raw frame's label mask (``masks/NNNNNN.png``: ids in ``manifest['mask_labels']``)."""
    speech: str | None = None
    """A speech recording (WAV) whose phones time the motion (:mod:`lipgen.speech`)."""
    speech_text: str | None = None
    """The transcript of ``speech``, or, alone, English text spoken with Klatt-rule durations."""
    subject_seed: int | None = None
    """Draws the subject's own lip shape and ink-dot placement (:mod:`lipgen.subject.shape`); None:
    the model's shape with the dots on its marker nodes (the data before subject seeds existed)."""
    truth_physics: str = "linear"
    """``"linear"`` (the linear truth subject) or ``"layer"`` (the nonlinear tissue layer,
    :mod:`lipgen.subject.layer`; about 0.06 s of CPU per frame)."""
    motion_sources: str = "gestures"
    """``"gestures"`` (:func:`lipgen.subject.activation.random_activations`, the motion before
    presets) or ``"independent"`` (:mod:`lipgen.subject.independent`: speech from independent
    asymmetric sources plus a stochastic residual; a script or speech adds the residual only)."""
    preset: str | None = None
    """The preset these settings came from (:mod:`lipgen.dataset.presets`), recorded as such;
    None is ``easy`` (the data before presets, whose manifests name none)."""
    renderer: str = "pyrender"
    """``"pyrender"`` (OpenGL) or ``"cycles"`` (Blender Cycles on the CPU: path tracing, subsurface
    scattering in skin and lips; depth and masks rasterised from the same scene by pyrender);
    :mod:`lipgen.rig.backends`."""
    cycles_samples: int = 16
    """Cycles' path-tracing samples per pixel (denoised); used with ``renderer="cycles"``."""

    conditions: ImageConditions = ImageConditions()
    """Lens, mirror, light and sensor (:mod:`lipgen.rig.conditions`); the default is the ideal camera."""

    @classmethod
    def from_preset(cls, name: str, **overrides) -> GenerateSettings:
        """Settings of preset ``name`` (``easy``, ``default``, ``hard``), any field overridden by
        ``overrides`` (those that are not None)."""
        from lipgen.dataset.presets import get_preset

        p = get_preset(name)
        base = {"head_rotation_deg": p.motion.head_rotation_deg,
                "head_translation_mm": p.motion.head_translation_mm, "noise": p.image.noise,
                "dot_diameter": p.image.dot_diameter, "conditions": p.image.conditions,
                "truth_physics": "layer" if p.subject.nonlinear_physics else "linear",
                "motion_sources": p.motion.sources,
                "subject_seed": p.subject.default_subject_seed if p.subject.own_shape else None}
        given = {k: v for k, v in overrides.items() if v is not None}
        distorted = p.image.conditions.lens_distortion is not None
        if distorted and not {"calib_frames", "lens_frames"} & set(given):
            base.update(calib_frames=PRESET_CALIB_FRAMES, lens_frames=PRESET_LENS_FRAMES)
        if not p.subject.own_shape and given.get("subject_seed") is not None:
            raise ValueError(f"preset {name!r} films the model's own shape; a subject seed needs preset "
                             "'default' or 'hard'")
        # easy is the data before presets, byte for byte: its manifest names no preset
        return cls(**{**base, **given, "preset": None if p.name == "easy" else p.name})

    def __post_init__(self) -> None:
        def whole(name, lo, hi):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or not lo <= v <= hi:
                raise ValueError(f"{name} must be a whole number in [{lo}, {hi}], got {v!r}")

        whole("frames", 1, 10**6)
        whole("seed", 0, 2**63 - 1)
        whole("subject_resolution", 1, 4)
        whole("calib_frames", 0, 1000)
        whole("lens_frames", 0, 1000)
        if self.lens_frames and self.calib_frames - self.lens_frames < 1:
            raise ValueError(f"lens_frames ({self.lens_frames}) must leave at least one of the calib_frames "
                             f"({self.calib_frames}) with the board seen in both views (the world frame)")
        whole("png_compress_level", 0, 9)
        whole("cycles_samples", 1, 4096)
        from lipgen.rig.backends import RENDERERS

        if self.renderer not in RENDERERS:
            raise ValueError(f"unknown renderer {self.renderer!r}; choose one of {RENDERERS}")
        if self.subject_seed is not None:
            from lipgen.subject.shape import MAX_SUBJECT_SEED

            whole("subject_seed", 0, MAX_SUBJECT_SEED)
        if self.truth_physics not in ("linear", "layer"):
            raise ValueError(f"truth_physics must be 'linear' or 'layer', got {self.truth_physics!r}")
        if self.motion_sources not in ("gestures", "independent"):
            raise ValueError(f"motion_sources must be 'gestures' or 'independent', got "
                             f"{self.motion_sources!r}")
        if self.preset is not None:
            from lipgen.dataset.presets import get_preset

            get_preset(self.preset)
        w, h = (int(x) for x in self.size)
        if w < 16 or h < 12 or w * 3 != h * 4:
            raise ValueError(f"size must be W x H with a 4:3 aspect (the default rig), e.g. 640x480; "
                             f"got {w}x{h}")
        if w > MAX_WIDTH:  # OpenGL draws both views side by side (about 1.07 W wide); its limit is 16384
            raise ValueError(f"size {w}x{h} is wider than the renderer can draw; at most "
                             f"{MAX_WIDTH}x{MAX_WIDTH * 3 // 4}")
        object.__setattr__(self, "size", (w, h))
        for name, lo, hi in (("fps", 1, 1000), ("head_rotation_deg", 0, 30), ("head_translation_mm", 0, 50),
                             ("noise", 0, 50), ("dot_diameter", 0.2, 10)):
            v = float(getattr(self, name))
            if not lo <= v <= hi:
                raise ValueError(f"{name} must be in [{lo}, {hi}], got {v}")
            object.__setattr__(self, name, v)
        if self.script is not None and (self.speech or self.speech_text):
            raise ValueError("choose one source of motion: a viseme script or speech, not both")
        if self.script is not None:
            from lipgen.subject.motion import parse_script

            parse_script(self.script)  # unknown visemes: a clear error now, not after the simulation
        for name in ("depth", "masks"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be True or False, got {getattr(self, name)!r}")
        c, r, sq = self.board
        object.__setattr__(self, "board", (int(c), int(r), float(sq)))
        if isinstance(self.conditions, dict):  # as to_dict() writes it
            object.__setattr__(self, "conditions", ImageConditions.from_dict(self.conditions))
        if not isinstance(self.conditions, ImageConditions):
            raise TypeError(f"conditions must be ImageConditions, got {type(self.conditions).__name__}")

    def to_dict(self) -> dict:
        """The settings as a JSON-ready dict (as stored in the manifest)."""
        d = asdict(self)
        d["size"], d["board"] = list(self.size), list(self.board)
        for key in ("speech", "speech_text"):  # absent, as in manifests written before they existed
            if d[key] is None:
                del d[key]
        for k, unset in (("lens_frames", 0), ("subject_seed", None), ("truth_physics", "linear"),
                         ("motion_sources", "gestures"),
                         ("preset", None), ("renderer", "pyrender")):
            if d[k] == unset:  # unset: the manifest of such data is as it always was
                del d[k]
        if self.renderer == "pyrender" and self.cycles_samples == 16:
            del d["cycles_samples"]  # pyrender data: the manifest is as it always was
        d["conditions"] = self.conditions.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: dict) -> GenerateSettings:
        """Settings from a manifest's dict, checking every key and value."""
        if not isinstance(d, dict):
            raise ValueError(f"generator settings must be a JSON object, got {type(d).__name__}")
        known = {f.name for f in fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"unknown generator settings {sorted(unknown)}")
        return cls(**{k: tuple(v) if k in ("size", "board") else v for k, v in d.items()})
