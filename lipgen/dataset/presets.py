"""Difficulty presets: subject, motion and image conditions chosen together (``--preset``).

A :class:`Preset` groups three frozen dataclasses, so each stage's conditions stay separate:
who is filmed (:class:`SubjectConditions`), how they move (:class:`MotionConditions`) and how the
frames are formed (:class:`FrameConditions`, whose lens, mirror, light and sensor are one
:class:`~lipgen.rig.conditions.ImageConditions`).

- ``easy``: the data as lipgen made it before presets, byte for byte: the truth has the model's
  rest shape, ink dots on the model's marker nodes and the linear truth physics, filmed by the
  ideal camera (pinhole, fixed light, Gaussian noise of one grey level, PNG). Kept for regression.
- ``default``: the subject has its own shape (:mod:`lipgen.subject.shape`) and hand-placed dots
  at surface points 1-2 mm from the model's markers (:mod:`lipgen.subject.inkdots`), moves by
  speech from independent asymmetric sources with a stochastic residual
  (:mod:`lipgen.subject.independent`: 10 learned modes hold about 99.2 % of it), filmed like
  a good laboratory recording: a mild lens, slight defocus and motion blur, light varying per
  dataset, a real mirror, a low-noise sensor, high-quality JPEG; the subject has a head (cheeks,
  chin, nasolabial folds, a nose with nostrils), teeth and a tongue, and hand-drawn ink dots.
- ``hard``: as ``default``, moved by the nonlinear truth physics (:mod:`lipgen.subject.layer`:
  large deformation, near-incompressible, lip contact; about 0.06 s of CPU per frame), with more head
  motion, filmed by an ordinary camera: a wide lens with visible radial and tangential
  distortion, defocus (the mirror view is farther than the focus), 1/120 s exposure at 30
  frames/s (motion blur), light, exposure and white balance varying per dataset, a
  back-silvered mirror with tint, ghost and edge, shot and read noise of a small sensor, Bayer
  demosaicing and JPEG at quality 85; the lights cast shadows, and the ink dots are irregular and
  smudge over the clip. Its exposure's instants are at most 2 px of a mark's motion apart
  (``blur_step_px``; 1 px in ``default``), measured against a dense reference on its own frames
  (``lipgen bench --suite presets``, ``fidelity``; :mod:`lipgen.bench.preset_fidelity`): on the
  face's pixels the noise-free frame moves by 0.59 grey levels RMS against instants 0.25 px
  apart (0.46 at 1 px), well under the sensor's own shot and read noise there (2.24 grey levels;
  3.45 with Bayer and JPEG), and the ink dots' centroids by 0.07 px RMS (0.05 at 1 px). At 1/120 s
  a mark's image moves 0.5-0.6 px (median) and at most 2.6 px in a frame of hard seeds 7-8, so
  most hard frames are one instant. A coarser head (``head_mesh`` 28, 3, 36, 64: 0.92 grey
  levels against a mesh 1.5 times finer, 0.77 for the default mesh) was measured and not taken:
  on validation seed 7 it flipped the first-frame registration (26 % -> 2.5 % of sightings
  accepted), though it moves no dot centroid by more than 0.04 px.

Image values follow published camera figures: phone and webcam lenses have k1 of -0.1 to -0.3
and tangential terms around 1e-3 (decentring); small sensors hold 5,000 to 10,000 electrons per
pixel; back-silvered mirrors reflect about 85-90 % with a 4 % front-surface ghost.

The manifest records the preset's name and every setting it implies.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from lipgen.rig.conditions import ImageConditions

__all__ = ["SubjectConditions", "MotionConditions", "FrameConditions", "Preset", "PRESETS", "get_preset",
           "preset_names"]


@dataclass(frozen=True)
class SubjectConditions:
    """Who is filmed."""

    own_shape: bool = False
    """Draw the subject's lip shape and dot placement from the subject seed (else the model's)."""
    nonlinear_physics: bool = False
    """Move the truth with the nonlinear tissue layer (else the linear truth subject)."""
    default_subject_seed: int = 0
    """The subject seed used when none is given (with ``own_shape``)."""


@dataclass(frozen=True)
class MotionConditions:
    """How the subject moves (the muscle-like actions come from :mod:`lipgen.subject`)."""

    head_rotation_deg: float = 4.0
    head_translation_mm: float = 4.0
    sources: str = "gestures"
    """``"gestures"``: :func:`lipgen.subject.activation.random_activations` (the motion before
    presets); ``"independent"``: speech from 22 independent, asymmetric sources plus a stochastic
    residual (:mod:`lipgen.subject.independent`)."""


@dataclass(frozen=True)
class FrameConditions:
    """How the frames are formed."""

    noise: float = 1.0
    """Extra Gaussian noise, grey levels (standard deviation); the sensor model is in ``conditions``."""
    dot_diameter: float = 2.0
    """Ink dot diameter, mm."""
    conditions: ImageConditions = ImageConditions()
    """Lens, mirror, light and sensor (the default is the ideal camera)."""


@dataclass(frozen=True)
class Preset:
    """A named set of conditions; see the module docstring."""

    name: str
    subject: SubjectConditions = SubjectConditions()
    motion: MotionConditions = MotionConditions()
    image: FrameConditions = FrameConditions()

    def to_dict(self) -> dict:
        """The preset as a JSON-ready dict (as recorded in the manifest)."""
        return asdict(self)


PRESETS: dict[str, Preset] = {
    "easy": Preset("easy"),
    "default": Preset(
        "default", SubjectConditions(own_shape=True), MotionConditions(sources="independent"),
        FrameConditions(noise=0.0, conditions=ImageConditions(
            distortion=(-0.08, 0.03, 0.0005, -0.0003, 0.0), focus_mm=330.0, aperture_px=6.0,
            shutter=0.15, blur_samples=3, light_jitter=0.3, mirror_reflectance=0.88,
            mirror_tint=(0.96, 1.0, 0.97), ghost=0.02, glass_mm=2.0, full_well=20000.0, read_noise=1.0,
            codec="jpeg", jpeg_quality=95, texture=0.6, head=True, mouth=True, ink=0.5, smudge=0.2))),
    "hard": Preset(
        "hard", SubjectConditions(own_shape=True, nonlinear_physics=True),
        MotionConditions(head_rotation_deg=8.0, head_translation_mm=6.0, sources="independent"),
        FrameConditions(noise=0.0, conditions=ImageConditions(
            distortion=(-0.15, 0.10, 0.0012, -0.0008, 0.0), focus_mm=340.0, aperture_px=12.0,
            shutter=0.25, blur_samples=5, blur_step_px=2.0, light_jitter=1.0, mirror_reflectance=0.85,
            mirror_tint=(0.93, 1.0, 0.95), ghost=0.04, glass_mm=3.0, mirror_extent_mm=(90.0, 110.0),
            full_well=6000.0, read_noise=1.5, bayer=True, codec="jpeg", jpeg_quality=85, texture=1.0,
            shadows=True, head=True, mouth=True, ink=1.0, smudge=0.5))),
}
"""The presets by name."""


def get_preset(name) -> Preset:
    """The preset called ``name``; ``ValueError`` naming the known ones otherwise."""
    if not isinstance(name, str) or name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose one of {', '.join(PRESETS)}")
    return PRESETS[name]


def preset_names() -> tuple[str, ...]:
    """The presets' names, easiest first."""
    return tuple(PRESETS)
