"""Difficulty presets of ``lipgen generate --preset easy|default|hard``.

A preset is a set of :class:`~lipgen.dataset.layout.GenerateSettings` fields. This module
defines the image conditions of each (lens, mirror, light, sensor: :mod:`lipgen.rig.conditions`);
other fields (subject, motion) can join the same entries.

- ``easy``: today's ideal frames (pinhole, fixed light, Gaussian noise of one grey level, PNG);
  it equals ``GenerateSettings()`` and reproduces earlier datasets byte for byte.
- ``default``: a good laboratory recording: a mild lens, slight defocus and motion blur, light
  varying per dataset, a real mirror, a low-noise sensor, high-quality JPEG.
- ``hard``: an ordinary camera: a wide lens with visible radial and tangential distortion,
  defocus (the mirror view is farther than the focus), 1/120 s exposure at 30 frames/s (motion
  blur), light, exposure and white balance varying per dataset with shadows, a back-silvered
  mirror with tint, ghost and edge, shot and read noise of a small sensor, Bayer demosaicing and
  JPEG at quality 85.

Values follow published camera figures: phone and webcam lenses have k1 of -0.1 to -0.3 and
tangential terms around 1e-3 (decentring); small sensors hold 5,000 to 10,000 electrons per
pixel; back-silvered mirrors reflect about 85-90 % with a 4 % front-surface ghost.
"""

from __future__ import annotations

from dataclasses import replace

from lipgen.dataset.layout import GenerateSettings
from lipgen.rig.conditions import ImageConditions

__all__ = ["PRESETS", "preset_settings", "preset_names"]

PRESETS: dict[str, dict] = {
    "easy": {},
    "default": {
        "noise": 0.0,
        "conditions": ImageConditions(
            distortion=(-0.08, 0.03, 0.0005, -0.0003, 0.0), focus_mm=330.0, aperture_px=6.0,
            shutter=0.15, blur_samples=3, light_jitter=0.3, mirror_reflectance=0.88,
            mirror_tint=(0.96, 1.0, 0.97), ghost=0.02, glass_mm=2.0, full_well=20000.0, read_noise=1.0,
            codec="jpeg", jpeg_quality=95, texture=0.6),
    },
    "hard": {
        "noise": 0.0,
        "conditions": ImageConditions(
            distortion=(-0.15, 0.10, 0.0012, -0.0008, 0.0), focus_mm=340.0, aperture_px=12.0,
            shutter=0.25, blur_samples=5, light_jitter=1.0, mirror_reflectance=0.85,
            mirror_tint=(0.93, 1.0, 0.95), ghost=0.04, glass_mm=3.0, mirror_extent_mm=(90.0, 110.0),
            full_well=6000.0, read_noise=1.5, bayer=True, codec="jpeg", jpeg_quality=85, texture=1.0),
    },
}


def preset_names() -> tuple[str, ...]:
    return tuple(PRESETS)


def preset_settings(name: str, **overrides) -> GenerateSettings:
    """The settings of preset ``name``, with any other fields given in ``overrides``.

    Raises
    ------
    ValueError
        ``name`` is not a preset.
    """
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose one of {', '.join(PRESETS)}")
    return replace(GenerateSettings(), **(PRESETS[name] | overrides))
