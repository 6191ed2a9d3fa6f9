"""Speech-like motion from independent sources: the motion of the ``default`` and ``hard`` presets.

The gestures of :func:`lipgen.subject.activation.random_activations` use about 13 independent
sources (its two-sided actions are exact sums of their one-sided halves and the jaw shift is one
signed DOF), so 10 learned modes hold 99.95 % of their variance, far above the 99.2 % the thesis
measured on a real speaker (Basu 1997, §5). This module drives the subject by
:data:`INDEPENDENT_SOURCES` instead:

- **Speech** (:func:`lipgen.subject.speech_timing.random_speech`: consonant-vowel syllables at
  4-6 per second, coarticulated by critically damped dynamics). Each bilateral muscle of a viseme
  is split into its left and right actions, each side with its own gain per syllable (log-normal,
  25 %): lip movements of speech are asymmetric by 10-30 % from speaker to speaker and moment to
  moment (Graves, Goodglass & Landis, "Mouth asymmetry during spontaneous speech",
  Neuropsychologia 20, 1982; Wolf & Goodale, "Oral asymmetries during verbal and non-verbal
  movements of the mouth", Neuropsychologia 25, 1987).
- **A jaw that opens 20 mm and more**: the jaw's activation is the viseme's times
  :data:`JAW_GAIN`, so an open vowel lowers the lower lip by about 20-25 mm, as in read and loud
  speech (lower-lip and jaw displacements of 10-25 mm: Westbury, "X-ray microbeam speech
  production database user's handbook", 1994; Ostry & Munhall, JASA 77, 1985). The jaw rotates
  about its hinge and glides forward (:mod:`lipgen.subject.sources`).
- **Independent gestures** of every source (:data:`INDEPENDENT_SOURCES`, 22 of them: 8 muscles on
  each side, lip roll-in of each lip, upper and lower lip protrusion, jaw opening and a signed jaw
  shift), random in time as in :func:`~lipgen.subject.activation.random_activations`: the
  non-speech movements between and over the words.
- **A stochastic residual** (:func:`residual_motion`): local random bulges of the soft tissue,
  independent in space and smooth in time, that no small linear basis explains. Its amplitude
  :data:`RESIDUAL_MM` is the one subject setting taken from the thesis: it was set on the
  development seeds 100-104 (subject seed = motion seed) so that 10 modes learned from the first
  140 frames of a 150-frame clip hold the 99.2 % the thesis measured: 0.65 mm gives 99.20 % on
  them (98.95-99.45 %), and 99.30 % (98.93-99.51 %) on the seeds 0-7 not used to set it; without
  the residual the sources alone hold 99.89 %. ``lipgen experiment table51 --preset default``
  reports the figure of its own run ("10 modes hold").

Checked against published lip kinematics (:mod:`lipgen.experiments.table51_kinematics`,
``renders/examples/table51_kinematics``; nothing changed by it): rounding narrows the mouth as it
protrudes the lips (protrusion and mouth width anti-correlated, r about -0.7 across frames);
protrusion also comes with a wide opening, as in /ʃ/ (Toda, Maeda, Carlen & Meftahi, ICPhS 2003:
protrusion with rounding and protrusion with opening are autonomous gestures), and lip separation
and protrusion rise together over the consonants (Westbury, Severson & Hashi, ICPhS 1999); the
jaw's sideways shift is small and independent of the other motions (Vatikiotis-Bateson & Ostry,
J. Phonetics 23, 1995).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from lipgen.subject.activation import DEFAULT_FPS, _check_fps, _viseme_vector, action_index

__all__ = ["INDEPENDENT_SOURCES", "BILATERAL", "JAW_GAIN", "RESIDUAL_MM", "independent_activations",
           "residual_motion", "simulate_independent"]

BILATERAL: dict[str, tuple[str, str]] = {
    name: (f"{name}_left", f"{name}_right")
    for name in ("upper_lip_raiser", "lip_corner_puller", "lip_corner_depressor", "pucker", "funneler",
                 "lip_press")}
"""Two-sided action of the visemes -> its (left, right) actions, which replace it here."""

INDEPENDENT_SOURCES: tuple[str, ...] = (
    "jaw_open", "jaw_shift",
    *[a for pair in BILATERAL.values() for a in pair],
    "lower_lip_depressor_left", "lower_lip_depressor_right", "lip_stretcher_left", "lip_stretcher_right",
    "upper_lip_roll_in", "lower_lip_roll_in", "upper_lip_protrusion", "lower_lip_protrusion",
)
"""The sources of this motion (``jaw_shift`` is signed: ``jaw_shift_left`` or ``_right``)."""

JAW_GAIN = 1.7
"""Jaw activation per unit of a viseme's ``jaw_open`` (1 = 14 mm at the lower-lip marker)."""

RESIDUAL_MM = 0.65
"""RMS (over frames and dots) of the residual deformation at the ink dots, mm (see the module)."""

_SIDE_SIGMA = 0.25  # per-syllable log-normal spread of each side's gain
_SIGMA_MM = (2.0, 4.0)  # size of the residual's bulges, mm
_TAPER_MM = 3.0  # the residual fades over this distance from the held nodes
_PROTRUSION_SHARE = 0.6  # upper-lip protrusion per unit of a viseme's pucker (rounded vowels)
_GESTURES_PER_SECOND = 0.45  # independent gestures per source per second (as random_activations)


def _bumps(rng, t: np.ndarray, rate: float, dur=(0.15, 0.6), peak=(0.15, 0.8)) -> np.ndarray:
    """(F,) a sum of raised-cosine bumps at Poisson times (``rate`` per second)."""
    span = t[-1] + (t[1] - t[0] if len(t) > 1 else 1.0)
    k = rng.poisson(rate * span)
    start = rng.uniform(-0.3, span, size=k)
    d = rng.uniform(*dur, size=k)
    p = rng.uniform(*peak, size=k)
    phase = (t[:, None] - start) / d
    return np.where((phase > 0) & (phase < 1), 0.5 - 0.5 * np.cos(2 * np.pi * phase), 0.0) @ p


def independent_activations(n_frames: int, seed=0, fps: float = DEFAULT_FPS,
                            syllables_per_second: float | None = None, jaw_gain: float = JAW_GAIN,
                            gestures_per_second: float = _GESTURES_PER_SECOND) -> np.ndarray:
    """Activations ``(F, A)`` (columns :data:`~lipgen.subject.activation.ACTIONS`) of random
    speech plus independent gestures of every source of :data:`INDEPENDENT_SOURCES`.

    ``syllables_per_second``: the speech rate (1-8; drawn from 4-6 if None). The two-sided
    actions of :data:`BILATERAL` stay 0 (their sides move instead); values lie in [0, 2].
    """
    from lipgen.subject.speech_timing import coarticulate, random_speech

    n_frames = int(n_frames)
    if n_frames < 1:
        raise ValueError(f"n_frames must be >= 1, got {n_frames}")
    fps = _check_fps(fps)
    if not np.isfinite(jaw_gain) or not 0 < jaw_gain <= 2:
        raise ValueError(f"jaw_gain must be in (0, 2], got {jaw_gain}")
    rng = np.random.default_rng(seed)
    s_rng, g_rng, b_rng = rng.spawn(3)
    rate = float(s_rng.uniform(4.0, 6.0)) if syllables_per_second is None else syllables_per_second
    _, seq = random_speech(n_frames, s_rng, fps, rate)  # checks the rate
    ends = np.cumsum([d for _, d in seq])
    times = (np.arange(n_frames) + 0.5) / fps
    which = np.minimum(np.searchsorted(ends, times, side="right"), len(seq) - 1)
    table = np.stack([_viseme_vector(name) for name, _ in seq]) * g_rng.uniform(0.7, 1.2, (len(seq), 1))
    gains = np.exp(g_rng.normal(0.0, _SIDE_SIGMA, (len(seq), 2)))
    for both, sides in BILATERAL.items():
        col = table[:, action_index(both)].copy()
        table[:, action_index(both)] = 0.0
        for k, side in enumerate(sides):
            table[:, action_index(side)] += col * gains[:, k]
    rounding = table[:, action_index("pucker_left")]  # (the left side's gain: lip rounding)
    table[:, action_index("upper_lip_protrusion")] += _PROTRUSION_SHARE * rounding
    table[:, action_index("jaw_open")] *= jaw_gain
    A = coarticulate(table[which], fps)
    t = np.arange(n_frames) / fps
    for name in INDEPENDENT_SOURCES:
        r = b_rng.spawn(1)[0]
        if name == "jaw_shift":
            shift = _bumps(r, t, gestures_per_second, peak=(-0.8, 0.8))
            A[:, action_index("jaw_shift_left")] += np.maximum(shift, 0.0)
            A[:, action_index("jaw_shift_right")] += np.maximum(-shift, 0.0)
        else:
            A[:, action_index(name)] += _bumps(r, t, gestures_per_second)
    A = np.clip(A, 0.0, None)
    return np.where(A < 1.5, A, 1.5 + 0.5 * np.tanh((A - 1.5) / 0.5))  # a smooth saturation below 2


def residual_motion(subject, n_frames: int, seed=0, fps: float = DEFAULT_FPS, rms_mm: float = RESIDUAL_MM,
                    n_components: int = 64, correlation_s: float = 0.08) -> np.ndarray:
    """(F, n, 3) a smooth random deformation of ``subject``'s surface, mm.

    ``n_components`` local bulges of the soft tissue (Gaussian displacement fields of σ 2-4 mm
    about random free nodes, in random directions, fading to 0 within about 3 mm of the nodes the
    subject's physics holds), each driven by its own zero-mean Gaussian process (white noise
    smoothed by a Gaussian of ``correlation_s`` seconds), scaled so that the RMS over frames and
    ink dots is ``rms_mm``. They are not elastic responses of the subject's physics (which a few
    of its low modes would explain), so no small basis holds them.
    """
    n_frames = int(n_frames)
    if n_frames < 1:
        raise ValueError(f"n_frames must be >= 1, got {n_frames}")
    fps = _check_fps(fps)
    if not np.isfinite(rms_mm) or not 0 <= rms_mm <= 5:
        raise ValueError(f"rms_mm must be in [0, 5] mm, got {rms_mm}")
    mesh = subject.mesh
    n = mesh.n_nodes
    if rms_mm == 0:
        return np.zeros((n_frames, n, 3))
    rng = np.random.default_rng(seed)
    X = mesh.vertices
    movable = np.setdiff1d(np.arange(n), subject.physics.mesh.anchors)
    centres = X[rng.choice(movable, n_components, replace=False)]
    sigma = rng.uniform(_SIGMA_MM[0], _SIGMA_MM[1], n_components)
    direction = rng.normal(size=(n_components, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    from scipy.spatial import cKDTree

    held = subject.physics.mesh.anchors
    free = 1.0 - np.exp(-cKDTree(X[held]).query(X)[0] ** 2 / (2 * _TAPER_MM**2))  # 0 where held
    w = np.exp(-np.sum((X[None] - centres[:, None]) ** 2, axis=-1) / (2 * sigma[:, None] ** 2))
    responses = (w * free)[..., None] * direction[:, None, :]  # (K, n, 3) local bulges
    pad = int(np.ceil(4 * correlation_s * fps))
    noise = rng.normal(size=(n_frames + 2 * pad, n_components))
    k = np.exp(-0.5 * (np.arange(-pad, pad + 1) / max(correlation_s * fps, 1e-9)) ** 2)
    drive = np.stack([np.convolve(c, k / np.linalg.norm(k), mode="valid") for c in noise.T], axis=1)
    U = np.einsum("fk,kni->fni", drive[:n_frames], responses)
    at_dots = _at_dots(subject, U)
    return U * (rms_mm / np.sqrt(np.mean(np.sum(at_dots**2, axis=-1))))


def _at_dots(subject, U: np.ndarray) -> np.ndarray:
    """(F, 16, 3) the field ``U`` (F, n, 3) at the subject's ink dots."""
    if subject.dots is None:
        return U[:, subject.mesh.markers]
    from lipgen.subject.inkdots import dot_positions

    return dot_positions(subject.dots, subject.mesh.faces, U)


def simulate_independent(subject, n_frames: int, seed=0, head=None, fps: float = DEFAULT_FPS,
                         rms_mm: float = RESIDUAL_MM, activations=None, progress: bool = False):
    """Ground-truth frames (a :class:`~lipgen.subject.motion.Motion`) of ``subject`` moved by
    :func:`independent_activations` (or the given ``activations`` (F, A)) plus
    :func:`residual_motion`; ``head`` (F, 4, 4) as in :func:`~lipgen.subject.motion.simulate`."""
    from lipgen.subject.motion import simulate

    a_rng, r_rng = np.random.default_rng(seed).spawn(2)
    A = independent_activations(n_frames, a_rng, fps) if activations is None else activations
    motion = simulate(subject, A, head, fps=fps, progress=progress)
    V = motion.vertices + residual_motion(subject, motion.n_frames, r_rng, fps, rms_mm)
    V.setflags(write=False)
    return replace(motion, vertices=V)

