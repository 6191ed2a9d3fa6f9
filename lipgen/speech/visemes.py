"""Phones to visemes, and visemes to activations of the subject's muscle-like actions by dynamics.

**Phones to visemes.** :data:`PHONE_VISEMES` follows the viseme classes of the MPEG-4 facial
animation standard (ISO/IEC 14496-2, Annex C; I. S. Pandzic and R. Forchheimer, *MPEG-4 Facial
Animation*, 2002, table 2.4): p b m / f v / T D / t d / k g / tS dZ S / s z / n l / r / A: / e /
I / Q / U, with each class given the lipgen viseme (:data:`lipgen.subject.activation.VISEMES`) that shapes
the lips the same way. Diphthongs take two visemes, one each half. As MPEG-4 notes for its
tongue-made classes (t d, k g, n l), their lips are whatever the neighbouring sounds make them:
those phones (and h) set only the jaw (:data:`UNDERSPECIFIED`), and their lip actions keep
moving from where they are.

**Visemes to activations.** Each action follows a critically damped second-order system toward
the target of the phone being produced (the *target approximation* view of articulation: Y. Xu
and Q. E. Wang 2001; P. Birkholz, B. J. Kröger and C. Neuschaefer-Rube, "Model-based reproduction
of articulatory trajectories for consonant-vowel sequences", IEEE TASLP 19, 2011)::

    x'' = (T - x) / tau^2 - 2 x' / tau

solved exactly on each phone (the target is constant there). Coarticulation comes out of these
dynamics: a short phone is not reached, a long one is, neighbours blend, and nothing looks up a
shape. Time constants (:data:`TAU`): 20 ms for lip actions, 15 ms for the lower lip's own
actions and 30 ms for the jaw, ordered as measured by Birkholz and Hoole (Interspeech 2012: the
lower lip approaches its targets fastest, the jaw slowest), with magnitudes of the order of
the target-approximation fits above. Targets start :data:`LEAD` s before each acoustic phone,
since articulatory movements begin before their acoustic landmarks (A. Löfqvist and
V. L. Gracco, JASA 105, 1999, report lip-closing onsets well ahead of the acoustic closure).
"""

from __future__ import annotations

import numpy as np

from lipgen.speech.phones import PhoneTrack
from lipgen.subject.activation import ACTIONS, VISEMES, action_index

__all__ = ["PHONE_VISEMES", "UNDERSPECIFIED", "TAU", "LEAD", "viseme_track", "phone_targets",
           "activations", "frame_visemes"]

PHONE_VISEMES: dict[str, tuple[str, ...]] = {
    # vowels: MPEG-4 A: e I Q U, refined by lipgen's vowel visemes
    "AA": ("AA",), "AE": ("AE",), "AH": ("AH",), "AO": ("OH",), "EH": ("EH",), "ER": ("R",),
    "IH": ("IH",), "IY": ("EE",), "UH": ("OO",), "UW": ("OO",),
    "AW": ("AA", "OO"), "AY": ("AA", "IH"), "EY": ("EH", "IH"), "OW": ("OH", "OO"), "OY": ("OH", "EE"),
    # consonants by MPEG-4 class
    "P": ("M",), "B": ("M",), "M": ("M",), "F": ("F",), "V": ("F",), "TH": ("TH",), "DH": ("TH",),
    "CH": ("SH",), "JH": ("SH",), "SH": ("SH",), "ZH": ("SH",), "S": ("S",), "Z": ("S",),
    "R": ("R",), "W": ("W",), "Y": ("EE",),
    "T": ("L",), "D": ("L",), "N": ("L",), "L": ("L",), "K": ("L",), "G": ("L",), "NG": ("L",),
    "HH": ("AH",), "SIL": ("REST",),
}
"""ARPAbet phone -> lipgen viseme(s) (see the module doc for the source)."""

UNDERSPECIFIED: dict[str, tuple[str, ...]] = {
    "T": ("jaw_open",), "D": ("jaw_open",), "N": ("jaw_open",), "L": ("jaw_open",),
    "K": ("jaw_open",), "G": ("jaw_open",), "NG": ("jaw_open",), "HH": (),
}
"""Phones made by the tongue (or the glottis): only these actions get a target; the others
keep moving from where they are."""

TAU: dict[str, float] = {a: 0.020 for a in ACTIONS} | {
    "jaw_open": 0.030, "jaw_shift_left": 0.030, "jaw_shift_right": 0.030,
    "lower_lip_protrusion": 0.015, "lip_press": 0.015,
}
"""Time constant (s) of each action's critically damped response."""

LEAD = 0.04
"""Seconds by which each phone's articulatory target precedes its acoustic start."""


def _viseme_vector(name: str) -> np.ndarray:
    v = np.zeros(len(ACTIONS))
    for action, a in VISEMES[name].items():
        v[action_index(action)] = a
    return v


def viseme_track(phones: PhoneTrack) -> tuple[list[str], np.ndarray, np.ndarray, list[str]]:
    """(visemes, start (v,), end (v,), phone of each) with diphthongs split in halves."""
    names, start, end, of = [], [], [], []
    for label, a, b in zip(phones.labels, phones.start, phones.end, strict=True):
        parts = PHONE_VISEMES[label]
        step = (b - a) / len(parts)
        for k, v in enumerate(parts):
            names.append(v), start.append(a + k * step), end.append(a + (k + 1) * step), of.append(label)
    return names, np.array(start), np.array(end), of


def phone_targets(phones: PhoneTrack) -> tuple[np.ndarray, np.ndarray]:
    """(targets (v, A) with NaN where unspecified, start times (v,)) of the viseme segments."""
    names, start, _, of = viseme_track(phones)
    T = np.stack([_viseme_vector(n) for n in names])
    for i, label in enumerate(of):
        if label in UNDERSPECIFIED:
            keep = np.zeros(len(ACTIONS), bool)
            keep[[action_index(a) for a in UNDERSPECIFIED[label]]] = True
            T[i, ~keep] = np.nan
    return T, start


def _step(x, v, T, t, tau):
    """State (x, v) after time ``t`` of the critically damped system toward ``T``."""
    c1 = x - T
    c2 = v + c1 / tau
    e = np.exp(-t / tau)
    return T + (c1 + c2 * t) * e, (c2 - (c1 + c2 * t) / tau) * e


def activations(phones: PhoneTrack, fps: float = 30.0, n_frames: int | None = None,
                tau: dict[str, float] | None = None, lead: float = LEAD) -> np.ndarray:
    """Activations ``(F, A)`` in [0, 1] at ``fps`` for ``phones`` (module doc).

    Frame ``f`` is the state at time ``f / fps``; the mouth starts at rest. ``n_frames``
    defaults to cover the last phone.
    """
    fps = float(fps)
    if not np.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps must be a positive frame rate, got {fps}")
    if len(phones) == 0:
        raise ValueError("no phones to animate")
    taus = np.array([(tau or TAU).get(a, TAU[a]) for a in ACTIONS])
    if (taus <= 0).any():
        raise ValueError(f"time constants must be positive, got {dict(zip(ACTIONS, taus, strict=True))}")
    T, start = phone_targets(phones)
    start = np.maximum(start - lead, 0.0)
    start[0] = 0.0
    n = int(np.ceil(phones.duration * fps)) + 1 if n_frames is None else int(n_frames)
    times = np.arange(n) / fps
    seg = np.searchsorted(start, times, side="right") - 1
    x, v = np.zeros(len(ACTIONS)), np.zeros(len(ACTIONS))
    out = np.empty((n, len(ACTIONS)))
    for i in range(len(start)):
        target = np.where(np.isnan(T[i]), x, T[i])  # unspecified: come to rest where it is
        frames = np.flatnonzero(seg == i)
        if len(frames):
            out[frames], _ = _step(x, v, target, times[frames, None] - start[i], taus)
        if i + 1 < len(start):
            x, v = _step(x, v, target, start[i + 1] - start[i], taus)
    return np.clip(out, 0.0, 1.0)


def frame_visemes(phones: PhoneTrack, fps: float, n_frames: int) -> list[str]:
    """The viseme sounding at each frame time ``f / fps`` (for agreement scores)."""
    names, _, end, _ = viseme_track(phones)
    i = np.minimum(np.searchsorted(end, np.arange(n_frames) / fps, side="right"), len(names) - 1)
    return [names[k] for k in i]
