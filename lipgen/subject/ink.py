"""Ink dots as a pen leaves them: irregular edges, sizes that vary, and slow smudging over a clip.

:func:`ink_style` draws, per dataset seed, each dot's size factor and the shape of its edge (a
radius that wanders round the dot: harmonics 2-5 of a Fourier series, so the ink's centroid stays
on the marked surface point to second order: a first harmonic would move it) and the clip's
smudging: the ink spreads into a faint halo ring and pales a little as the clip goes on (skin oil
and lip contact). Smudging is symmetric, so the dot's centre is still the truth; it is what
makes the edge soft and the contrast fall. The style is recorded in the manifest.

Hand-drawn dots vary by about +-15 % in diameter; the edge wobbles by a few percent of the radius.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["InkStyle", "ink_style", "SECTORS"]

SECTORS = 24
"""Sectors of an irregular dot's outline."""
_HARMONICS = np.arange(2, 6)
_PALE = (0.30, 0.26, 0.26)  # what smudged ink tends to (sRGB)


@dataclass(frozen=True, eq=False)
class InkStyle:
    """Every dot's look.

    Attributes
    ----------
    scale : (k,) float
        Diameter factor of each dot (1: the nominal diameter).
    amplitude, phase : (k, 4) float
        Relative amplitude and phase (rad) of harmonics 2-5 of each dot's edge.
    halo : float
        Width of the smudge halo, as a fraction of a dot's radius.
    smudge : float
        Opacity the halo reaches at the end of the clip (0: no smudging).
    """

    scale: np.ndarray
    amplitude: np.ndarray
    phase: np.ndarray
    halo: float
    smudge: float

    def outline(self, k: int) -> np.ndarray:
        """(SECTORS,) radius factor round dot ``k`` (its size included)."""
        ang = 2 * np.pi * np.arange(SECTORS) / SECTORS
        wob = np.cos(ang[:, None] * _HARMONICS[None] + self.phase[k][None]) @ self.amplitude[k]
        return self.scale[k] * (1.0 + wob)

    def ink_color(self, ink, age: float) -> tuple[float, float, float]:
        """The ink's colour (sRGB) ``age`` (0..1) of the way through the clip."""
        w = 0.5 * self.smudge * float(np.clip(age, 0, 1))
        return tuple(float((1 - w) * a + w * b) for a, b in zip(ink, _PALE, strict=True))

    def halo_opacity(self, age: float) -> float:
        """Opacity of the halo ``age`` (0..1) of the way through the clip."""
        return float(self.smudge * np.clip(age, 0, 1))

    def to_dict(self) -> dict:
        """The style as a JSON-ready dict (as stored in the manifest)."""
        return {"scale": self.scale.tolist(), "edge_amplitude": self.amplitude.tolist(),
                "edge_phase": self.phase.tolist(), "edge_harmonics": _HARMONICS.tolist(),
                "halo": self.halo, "smudge": self.smudge}


def ink_style(seed, n_dots: int, strength: float, smudge: float = 0.0) -> InkStyle:
    """Draw the dots' :class:`InkStyle` from ``seed``.

    Parameters
    ----------
    seed : int or numpy.random.Generator
    n_dots : int
        Dots (markers and the nose).
    strength : float
        0..1: how irregular (1: sizes +-15 % (sd), edges wobbling by up to about 8 % of the radius).
    smudge : float
        0..1: the halo's opacity at the end of the clip.
    """
    if not 0 <= strength <= 1 or not 0 <= smudge <= 1:
        raise ValueError(f"ink strength and smudge must be in [0, 1], got {strength}, {smudge}")
    rng = np.random.default_rng(seed)
    scale = np.clip(np.exp(strength * 0.15 * rng.standard_normal(n_dots)), 0.7, 1.45)
    amp = strength * rng.uniform(0.0, 0.06, (n_dots, len(_HARMONICS))) / (_HARMONICS - 1)[None]
    phase = rng.uniform(0, 2 * np.pi, (n_dots, len(_HARMONICS)))
    return InkStyle(scale, amp, phase, 0.45 if smudge > 0 else 0.0, float(smudge))
