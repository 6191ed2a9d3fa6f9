"""Difficulty presets: subject, motion and image conditions chosen together (``--preset``).

A :class:`Preset` groups three frozen dataclasses, so each stage's conditions stay separate and
other work can add fields to its own part (image realism adds its lens, sensor and texture
settings to :class:`ImageConditions`):

- ``easy``: the data as lipgen made it before presets: the truth has the model's rest shape,
  ink dots on the model's marker nodes and the linear truth physics (kept for regression);
- ``default``: the subject has its own shape (:mod:`lipgen.subject.shape`) and hand-placed dots
  at surface points 1-2 mm from the model's markers (:mod:`lipgen.subject.inkdots`);
- ``hard``: as ``default``, moved by the nonlinear truth physics (:mod:`lipgen.subject.layer`:
  large deformation, near-incompressible, lip contact; slow: seconds per frame), with more head
  motion and sensor noise.

The manifest records the preset's name (``easy``, the data as before, names none) and every
setting it implies.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

__all__ = ["SubjectConditions", "MotionConditions", "ImageConditions", "Preset", "PRESETS", "get_preset"]


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


@dataclass(frozen=True)
class ImageConditions:
    """How the frames are formed."""

    noise: float = 1.0
    """Sensor noise, grey levels (standard deviation)."""
    dot_diameter: float = 2.0
    """Ink dot diameter, mm."""


@dataclass(frozen=True)
class Preset:
    """A named set of conditions; see the module docstring."""

    name: str
    subject: SubjectConditions = SubjectConditions()
    motion: MotionConditions = MotionConditions()
    image: ImageConditions = ImageConditions()

    def to_dict(self) -> dict:
        return asdict(self)


PRESETS: dict[str, Preset] = {
    "easy": Preset("easy"),
    "default": Preset("default", SubjectConditions(own_shape=True)),
    "hard": Preset("hard", SubjectConditions(own_shape=True, nonlinear_physics=True),
                   MotionConditions(head_rotation_deg=8.0, head_translation_mm=6.0),
                   ImageConditions(noise=2.0)),
}
"""The presets by name."""


def get_preset(name) -> Preset:
    """The preset called ``name``; ``ValueError`` naming the known ones otherwise."""
    if not isinstance(name, str) or name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose one of {', '.join(PRESETS)}")
    return PRESETS[name]
