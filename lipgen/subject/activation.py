"""Activation curves over time for the synthetic subject, and rigid head motion.

Activations are ``(F, A)`` arrays in [0, 1], one column per action of :data:`ACTIONS`, sampled
at ``fps`` frames per second (30 by default, as the thesis's video). Two sources:

- :func:`random_activations`: smooth random gestures (seeded);
- :func:`viseme_activations`: a viseme script such as ``"AA:0.3 EE:0.2 OO M:0.15 F REST:0.4"``.

:func:`head_motion` gives small smooth rigid head motions as (F, 4, 4) model-to-world poses.
"""

from __future__ import annotations

import re

import numpy as np

from lipgen._validate import as_float_array

__all__ = ["ACTIONS", "CLASSIC_ACTIONS", "ONE_SIDED", "VISEMES", "VISEME_ALIASES", "DEFAULT_FPS",
           "parse_script",
           "random_activations", "viseme_activations", "head_motion", "action_index"]

DEFAULT_FPS = 30.0
"""Frames per second of activation curves unless given."""

ACTIONS: tuple[str, ...] = (
    "jaw_open",              # jaw rotation with the lower-lip depressor: the lower lip drops
    "upper_lip_raiser",      # levator labii: the upper lip rises and everts
    "lip_corner_puller",     # zygomaticus major (smile): corners back, out and up
    "lip_corner_depressor",  # depressor anguli oris: corners down
    "pucker",                # orbicularis oris ring: the lips purse forward and in
    "lip_press",             # the lips pressed together, flattening, the lower lip pushed up
    "funneler",              # the lips flared forward into a funnel (as in "sh")
    "lower_lip_protrusion",  # mentalis: the lower lip pushed forward and up
    # One-sided variants (left = the subject's left, +x): real expressions are rarely symmetric.
    "upper_lip_raiser_left",
    "upper_lip_raiser_right",
    "lip_corner_puller_left",     # a one-sided smile
    "lip_corner_puller_right",
    "lip_corner_depressor_left",
    "lip_corner_depressor_right",
    "jaw_shift_left",        # lateral jaw excursion toward the subject's left (a rigid shift)
    "jaw_shift_right",
    # Independent sources of the speech-like motion (lipgen.subject.independent): the sphincter
    # and the lower-lip muscles on one side each, and midline actions of each lip.
    "pucker_left",                # orbicularis oris, one side: that half purses
    "pucker_right",
    "funneler_left",
    "funneler_right",
    "lip_press_left",
    "lip_press_right",
    "lower_lip_depressor_left",   # depressor labii inferioris: the lower lip down and everted
    "lower_lip_depressor_right",
    "lip_stretcher_left",         # risorius: the corner drawn straight out
    "lip_stretcher_right",
    "upper_lip_roll_in",          # the upper lip rolled in over the teeth (as for "p" in "apa")
    "lower_lip_roll_in",
    "upper_lip_protrusion",       # the upper lip pushed forward (rounded vowels)
)
"""The named muscle-like actions, in the column order of every activation array.

The first eight are symmetric; the ``_left``/``_right`` variants are the same muscles on one side
only, and the jaw shifts move the jaw sideways. New actions are appended, so the columns (and the
seeded random draws) of the older ones keep their place. :func:`random_activations` draws the
first 16 (:data:`CLASSIC_ACTIONS`) only; the later ones are the independent sources of
:mod:`lipgen.subject.independent`."""

CLASSIC_ACTIONS: tuple[str, ...] = ACTIONS[:16]
"""The actions :func:`random_activations` and the viseme scripts use (the motion before the
independent sources; the other columns stay 0)."""

ONE_SIDED: tuple[str, ...] = tuple(a for a in ACTIONS if a.endswith(("_left", "_right")))
"""The one-sided actions (drawn half as often as the others by :func:`random_activations`)."""

VISEMES: dict[str, dict[str, float]] = {
    "REST": {},
    "AA": {"jaw_open": 0.9, "lip_corner_puller": 0.1},
    "AE": {"jaw_open": 0.6, "lip_corner_puller": 0.35, "upper_lip_raiser": 0.2},
    "AH": {"jaw_open": 0.55},
    "EH": {"jaw_open": 0.4, "lip_corner_puller": 0.3},
    "EE": {"lip_corner_puller": 0.8, "jaw_open": 0.15, "upper_lip_raiser": 0.15},
    "IH": {"lip_corner_puller": 0.45, "jaw_open": 0.25},
    "OH": {"jaw_open": 0.5, "pucker": 0.45, "funneler": 0.4},
    "OO": {"pucker": 0.9, "funneler": 0.5, "jaw_open": 0.15},
    "W": {"pucker": 1.0, "funneler": 0.3},
    "M": {"lip_press": 0.9},
    "F": {"lip_press": 0.4, "upper_lip_raiser": 0.35, "jaw_open": 0.1},
    "TH": {"jaw_open": 0.2, "lower_lip_protrusion": 0.2},
    "S": {"lip_corner_puller": 0.3, "jaw_open": 0.1},
    "SH": {"funneler": 0.8, "lower_lip_protrusion": 0.5, "jaw_open": 0.15},
    "L": {"jaw_open": 0.35},
    "R": {"pucker": 0.4, "funneler": 0.3, "jaw_open": 0.2},
}
"""Viseme name -> activation of each action it uses (the others are 0)."""

VISEME_ALIASES: dict[str, str] = {"IY": "EE", "UW": "OO", "B": "M", "P": "M", "V": "F", "DH": "TH",
                                  "Z": "S", "CH": "SH", "JH": "SH", "ZH": "SH", "SIL": "REST",
                                  "-": "REST", "_": "REST"}
"""Other spellings accepted in scripts."""

DEFAULT_VISEME_SECONDS = 0.2
_TOKEN = re.compile(r"^([A-Za-z_\-]+)(?::([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?))?$")


def action_index(name: str) -> int:
    """Column of action ``name`` in activation arrays; ``ValueError`` listing the known ones."""
    if name not in ACTIONS:
        raise ValueError(f"unknown action {name!r}; the known actions are {', '.join(ACTIONS)}")
    return ACTIONS.index(name)


def _viseme_vector(name: str) -> np.ndarray:
    v = np.zeros(len(ACTIONS))
    for action, a in VISEMES[name].items():
        v[action_index(action)] = a
    return v


def parse_script(script: str) -> list[tuple[str, float]]:
    """Parse a viseme script into ``[(viseme, seconds), ...]``.

    The syntax is tokens separated by spaces or commas, each ``NAME`` or ``NAME:SECONDS``
    (``SECONDS`` defaults to 0.2). Names are case-insensitive; see :data:`VISEMES` and
    :data:`VISEME_ALIASES`. Example: ``"AA:0.3 EE:0.2 OO M:0.15 F REST:0.4"``.
    """
    if not isinstance(script, str):
        raise TypeError(f"script must be a string like 'AA:0.3 EE OO', got {type(script).__name__}")
    tokens = [t for t in re.split(r"[\s,]+", script.strip()) if t]
    if not tokens:
        raise ValueError("the viseme script is empty; write e.g. 'AA:0.3 EE:0.2 OO M F'")
    out = []
    for tok in tokens:
        m = _TOKEN.match(tok)
        if not m:
            raise ValueError(f"cannot read viseme token {tok!r}: write NAME or NAME:SECONDS, e.g. 'AA:0.3'")
        name = m.group(1).upper()
        name = VISEME_ALIASES.get(name, name)
        if name not in VISEMES:
            known = ", ".join(list(VISEMES) + list(VISEME_ALIASES))
            raise ValueError(f"unknown viseme {m.group(1)!r} in the script; the known visemes are {known}")
        seconds = DEFAULT_VISEME_SECONDS if m.group(2) is None else float(m.group(2))
        if not 0 < seconds < 3600:
            raise ValueError(f"viseme {tok!r} must last more than 0 s (and less than an hour)")
        out.append((name, seconds))
    return out


def _check_fps(fps: float) -> float:
    fps = float(fps)
    if not np.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps must be a positive frame rate, got {fps}")
    return fps


def _smooth(x: np.ndarray, width: int) -> np.ndarray:
    """Convolve each column with a unit-sum Hann window of ``width`` samples, zeros outside."""
    if width < 2:
        return x
    w = np.hanning(width + 2)[1:-1]
    w /= w.sum()
    return np.stack([np.convolve(col, w, mode="same") for col in x.T], axis=1)


def viseme_activations(script: str, fps: float = DEFAULT_FPS, coarticulation: float = 0.2) -> np.ndarray:
    """Activations ``(F, A)`` for a viseme script (see :func:`parse_script`).

    Each viseme holds its target for its duration; the step sequence is then smoothed with a
    Hann window of ``coarticulation`` seconds (neighbouring visemes blend, short ones are not
    fully reached). The mouth starts and ends at rest. ``F = round(total seconds * fps)``.
    """
    fps = _check_fps(fps)
    seq = parse_script(script)
    ends = np.cumsum([s for _, s in seq])
    n = max(1, int(round(ends[-1] * fps)))
    t = (np.arange(n) + 0.5) / fps
    which = np.minimum(np.searchsorted(ends, t, side="right"), len(seq) - 1)
    targets = np.stack([_viseme_vector(name) for name, _ in seq])[which]
    return np.clip(_smooth(targets, int(round(coarticulation * fps))), 0.0, 1.0)


def random_activations(n_frames: int, seed=0, fps: float = DEFAULT_FPS,
                       gestures_per_second: float = 0.45) -> np.ndarray:
    """Smooth random activations ``(F, A)`` in [0, 1]: seeded gestures of every action of
    :data:`CLASSIC_ACTIONS` (the other columns are 0).

    Each action gets gestures at random times (``gestures_per_second`` per action on average, the
    jaw twice as often, as in speech, the one-sided actions of :data:`ONE_SIDED` half as often;
    every symmetric action at least once, the one-sided ones only as drawn, so that a short clip
    is mostly symmetric and a long sequence mixes in asymmetric expressions), each a raised-cosine
    bump of 0.25-0.9 s and peak 0.2-1.0. Sums are saturated smoothly with tanh, so overlapping gestures
    stay below 1.
    """
    n_frames = int(n_frames)
    if n_frames < 1:
        raise ValueError(f"n_frames must be >= 1, got {n_frames}")
    fps = _check_fps(fps)
    rng = np.random.default_rng(seed)
    t = np.arange(n_frames) / fps
    span = n_frames / fps
    out = np.zeros((n_frames, len(ACTIONS)))
    if not np.isfinite(gestures_per_second) or gestures_per_second < 0:
        raise ValueError(f"gestures_per_second must be >= 0, got {gestures_per_second}")
    for a, name in enumerate(CLASSIC_ACTIONS):
        rate = gestures_per_second * (2.0 if name == "jaw_open" else 0.5 if name in ONE_SIDED else 1.0)
        # Every symmetric action appears at least once; the one-sided ones are occasional.
        k = (0 if name in ONE_SIDED else 1) + rng.poisson(rate * span)
        # One-sided gestures start within the clip, so that its first frame is symmetric (the
        # tracker and the normalisation take their layout from it, as a recording starts at rest).
        low = 0.0 if name in ONE_SIDED else -0.3
        start = rng.uniform(low, max(span - 0.3, low), size=k)
        dur = rng.uniform(0.25, 0.9, size=k)
        peak = rng.uniform(0.2, 1.0, size=k)
        phase = (t[:, None] - start) / dur
        bump = np.where((phase > 0) & (phase < 1), 0.5 - 0.5 * np.cos(2 * np.pi * phase), 0.0)
        out[:, a] = np.tanh(bump @ peak)
    return out


def _rotation(rx: float, ry: float, rz: float) -> np.ndarray:
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def head_motion(n_frames: int, seed=0, fps: float = DEFAULT_FPS, max_rotation_deg: float = 4.0,
                max_translation_mm: float = 4.0, pivot=(0.0, -70.0, -90.0)) -> np.ndarray:
    """Small smooth rigid head motion: ``(F, 4, 4)`` model-to-world poses.

    ``X_world = R (X_model - pivot) + pivot + t``: rotations about ``pivot`` (mm, model frame;
    by default near the top of the neck, behind and below the mouth) of up to
    ``max_rotation_deg`` about each axis (x nod, y turn, z tilt) and translations of up to
    ``max_translation_mm``, each a seeded sum of slow sinusoids (0.1-0.6 Hz).
    """
    n_frames = int(n_frames)
    if n_frames < 1:
        raise ValueError(f"n_frames must be >= 1, got {n_frames}")
    fps = _check_fps(fps)
    rng = np.random.default_rng(seed)
    t = np.arange(n_frames) / fps
    freq = rng.uniform(0.1, 0.6, size=(6, 3))
    phase = rng.uniform(0, 2 * np.pi, size=(6, 3))
    amp = rng.uniform(0.3, 1.0, size=(6, 3))
    curves = np.einsum("pk,fpk->fp", amp, np.sin(2 * np.pi * freq[None] * t[:, None, None] + phase))
    curves /= amp.sum(axis=1)  # each in [-1, 1]
    angles = np.deg2rad(max_rotation_deg) * curves[:, :3]
    shifts = max_translation_mm * curves[:, 3:]
    p = np.asarray(pivot, dtype=np.float64)
    poses = np.tile(np.eye(4), (n_frames, 1, 1))
    for f in range(n_frames):
        R = _rotation(*angles[f])
        poses[f, :3, :3] = R
        poses[f, :3, 3] = p - R @ p + shifts[f]
    return poses


def _activation_array(activations) -> np.ndarray:
    """(F, A) activations from an array or a mapping ``{action: (F,) curve}``."""
    if isinstance(activations, dict):
        for name in activations:
            action_index(name)
        curves = {k: np.atleast_1d(np.asarray(v, float)) for k, v in activations.items()}
        lengths = {len(v) for v in curves.values()}
        if len(lengths) != 1:
            raise ValueError(f"activation curves must all have the same length, got {sorted(lengths)}")
        n = lengths.pop()
        A = np.zeros((n, len(ACTIONS)))
        for k, v in curves.items():
            A[:, action_index(k)] = v
    else:
        A = as_float_array(activations, "activations")
        if A.ndim == 1 and len(A) == len(ACTIONS):
            A = A[None]
        if A.ndim != 2 or A.shape[1] != len(ACTIONS):
            raise ValueError(f"activations must have shape (F, {len(ACTIONS)}) with columns {ACTIONS}, "
                             f"or be a mapping action -> curve; got shape {A.shape}")
    as_float_array(A, "activations")
    if (A < 0).any() or (A > 2).any():
        raise ValueError(f"activations must lie in [0, 2] (1 is the calibrated full action), got range "
                         f"[{A.min():.3g}, {A.max():.3g}]")
    return A
