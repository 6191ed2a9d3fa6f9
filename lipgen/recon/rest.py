"""The subject's rest, estimated from training frames, and a metric normalisation.

:mod:`lipgen.recon.normalize` brings each frame into the model frame with one scale fitted on a
reference frame (the most neutral-looking, which is still a speaking frame) and measures the
displacement from the *model's* rest markers. A subject with lips of their own shape then carries
that shape difference as a constant displacement in every frame, and the speaking reference
frame's shape leaks into the scale.

Two truth-free corrections, both from training frames only:

- **Metric scale.** The rig is calibrated in millimetres (the board's squares), and the model is
  in millimetres: the scale between them is 1. Fitting a similarity to the model's markers
  instead reads the subject's lip size, and the reference frame's expression, as scale
  (:func:`metric_renormalize`: the head pose about the nose is fitted again at scale 1).
- **Rest from quiet frames** (:func:`quiet_rest`). Speech pauses return the lips to rest and hold
  them there, while a syllable moves them nearly all the time. The lips are slow in a pause and at
  a held target; the pauses all return to one posture, the targets are many. So the rest is each
  marker's median over the densest half (a least-median-of-squares location) of the slowest
  ``share`` of the frames (by the median marker speed), and displacements are measured from it.

Measured on the ``table51-pipeline`` recordings of subject seeds 7, 13 and 0 (preset ``default``,
640x480; the diagnosis seeds), normalised markers against the true model-frame marks (mm RMS over
the accepted sightings), the fitted scale -> scale 1: seed 7 training / utterance / other subject
2.48 -> 1.85, 3.83 -> 3.17, 3.86 -> 2.63; seed 13 4.75 -> 3.94, 4.17 -> 3.31, 5.37 -> 1.24;
seed 0 2.29 -> 1.92, 2.05 -> 1.52, 5.48 -> 4.03 (fitted scales 0.89-1.08). The displacements
from the quiet rest against the true ones: better where the tracking is good (seed 7 training,
90 % of sightings accepted: 2.05 -> 1.61 mm, from the model's rest -> from the quiet rest, both at
scale 1; seed 13's other subject 3.41 -> 1.83), worse where it is not (seed 13 training, 58 %:
2.73 -> 4.69; seed 0's other subject, 61 %: 4.93 -> 10.89): a marker locked on a still lure looks
quiet.

Re-measured on the tracker of 2026-12-03 (backfill, identity re-check), on validation subject
seeds 20 and 23 of ``table51-pipeline`` (never on its report's seeds 0-14): the per-marker
constant offset of the displacements against the truth (each marker's mean error over its
accepted sightings, RMS over the markers, mm), from the model's rest -> from the training
recording's quiet rest (:func:`quiet_rest`), both at scale 1: seed 20 training 3.35 -> 0.93,
its other utterance 3.82 -> 1.42 (its own quiet rest instead: 2.42); seed 23 training
2.42 -> 1.53, utterance 2.37 -> 1.61 (own: 2.24). The other subject's 40-frame recording, from
its own quiet rest: seed 20 3.27 -> 2.85, seed 23 2.06 -> 5.92 (1.3 s may hold no speech pause,
so its quiet frames are a held posture). So ``table51-pipeline`` now measures one subject's
recordings from its training recording's quiet rest (``rest="training"``, the default), and
another subject, who has no training recording, from the model's rest at scale 1.
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen._validate import as_float_array

__all__ = ["quiet_frames", "quiet_rest", "metric_renormalize", "measured_markers", "MIN_REST_FRAMES",
           "MIN_SIGHTINGS"]

log = logging.getLogger(__name__)

MIN_REST_FRAMES = 10
"""Quiet frames taken at least (:func:`quiet_rest`), so that a 40-frame recording has 5 rest frames."""
MIN_SIGHTINGS = 1 / 3
"""Share of the rest frames a marker must be measured in for a rest of its own (:func:`quiet_rest`)."""


def measured_markers(recon) -> np.ndarray:
    """(F, P) bool: the markers each frame's field reached (accepted and not a pose outlier)."""
    m = np.asarray(recon.visible, dtype=bool).copy()
    for f, j in recon.info.get("normalisation", {}).get("outliers", []):
        m[f, j] = False
    return m


def quiet_frames(markers, measured, share: float = 0.15) -> np.ndarray:
    """Indices of the slowest ``share`` of the frames (at least 3).

    Parameters
    ----------
    markers : (F, P, 3) float
        Normalised markers (mm), consecutive frames.
    measured : (F, P) bool
    share : float
        In (0, 1].

    Returns
    -------
    (k,) int
        Frames whose median marker speed ``|x_{t+1} − x_{t−1}| / 2`` (over the markers measured in
        all three frames) is among the lowest; the first and last frames have no speed.
    """
    X = as_float_array(markers, "markers", (None, None, 3), finite=False)
    m = np.asarray(measured, dtype=bool)
    if m.shape != X.shape[:2]:
        raise ValueError(f"measured must have shape {X.shape[:2]}, got {m.shape}")
    if not 0 < share <= 1:
        raise ValueError(f"share must be in (0, 1], got {share}")
    F = len(X)
    if F < 5:
        raise ValueError(f"need at least 5 consecutive frames to find quiet ones, got {F}")
    ok = m[2:] & m[:-2]
    v = np.where(ok, np.linalg.norm(X[2:] - X[:-2], axis=-1) / 2, np.nan)
    speed = np.full(F, np.inf)
    has = ok.sum(1) >= 3
    speed[1:-1][has] = np.nanmedian(v[has], axis=1)
    k = max(3, int(round(share * F)))
    return np.sort(np.argsort(speed, kind="stable")[:k])


def _densest_half(X, m, q) -> np.ndarray:
    """The half of the frames ``q`` that lie closest together: the frame whose ⌈k/2⌉-th nearest
    (RMS distance over the markers both measured) is nearest, and those neighbours."""
    k = (len(q) + 1) // 2
    D = np.full((len(q), len(q)), np.inf)
    for a, i in enumerate(q):
        both = m[q] & m[i]
        d2 = np.where(both[..., None], X[q] - X[i], 0.0) ** 2
        n = both.sum(1)
        D[a, n >= 3] = np.sqrt(d2.sum((1, 2))[n >= 3] / n[n >= 3])
    order = np.argsort(D, axis=1)
    radius = D[np.arange(len(q)), order[:, k - 1]]
    best = int(np.argmin(radius))
    return np.sort(q[order[best, :k]])


def quiet_rest(markers, measured, share: float = 0.15, min_frames: int = MIN_REST_FRAMES,
               min_sightings: float = MIN_SIGHTINGS, names=None, return_frames: bool = False):
    """(P, 3) each marker's median position over the rest frames, mm; NaN where it cannot be told.

    Parameters
    ----------
    markers : (F, P, 3) float
        Normalised markers (mm), consecutive frames of one recording (NaN where not measured).
    measured : (F, P) bool
        The accepted sightings (e.g. :func:`measured_markers`).
    share : float
        Share of the frames taken as quiet (:func:`quiet_frames`), in (0, 1].
    min_frames : int
        At least this many quiet frames (a short recording's share would leave too few).
    min_sightings : float
        A marker needs accepted sightings in at least this share of the rest frames (and in 2);
        else its row is NaN and a warning names it (the pipeline then takes the model's rest).
    names : sequence of str, optional
        The markers' names (P,), for that warning.
    return_frames : bool
        Also return the rest frames, (k,) int indices into ``markers``.

    Returns
    -------
    (P, 3) float
        The rest frames are the half of the quiet frames that lie closest together
        (the lips pass through a held vowel too, but return to the same rest
        in every pause); each marker's rest is its median over its accepted sightings there. A
        marker seen in too few of them is NaN: its median over all frames would be pulled by the
        motion (validation seeds 20 / 23, training recordings: 1.99 / 2.67 mm RMS per-marker
        offset, against 0.93 / 1.53 from the rest frames).
    """
    X = as_float_array(markers, "markers", (None, None, 3), finite=False)
    m = np.asarray(measured, dtype=bool) & np.all(np.isfinite(X), axis=-1)
    F, P = X.shape[:2]
    if not 0 <= min_sightings <= 1:
        raise ValueError(f"min_sightings must be a share in [0, 1], got {min_sightings}")
    if names is not None and len(names) != P:
        raise ValueError(f"names must name the {P} markers, got {len(names)}")
    share = min(1.0, max(share, int(min_frames) / max(F, 1)))
    q = _densest_half(X, m, quiet_frames(X, m, share))
    count = m[q].sum(axis=0)
    need = max(2, int(np.ceil(min_sightings * len(q))))
    out = np.full(X.shape[1:], np.nan)
    for j in np.flatnonzero(count >= need):
        out[j] = np.median(X[q[m[q, j]], j], axis=0)
    few = np.flatnonzero(count < need)
    if len(few):
        log.warning("rest from %d quiet frames: %s measured in fewer than %d of them; the model's rest is "
                    "used there", len(q), ", ".join(f"{names[j] if names is not None else f'marker {j}'} "
                                                    f"({count[j]})" for j in few), need)
    return (out, q) if return_frames else out


def metric_renormalize(recon, physics, rest=None, reference=None):
    """``recon`` normalised at scale 1 (the rig's millimetres) with its fields measured from ``rest``.

    Parameters
    ----------
    recon : Reconstruction
    physics : lipgen.Physics
        Of the model mesh.
    rest : (P, 3) float, optional
        The subject's rest markers in the model frame (e.g. :func:`quiet_rest` of the training
        recording; NaN rows: the model's). None: estimated from ``recon``'s own frames
        (:func:`quiet_rest`; a marker seen in too few rest frames takes the model's rest).
    reference : Reconstruction, optional
        Another recording of the same subject whose head rotation the pose fit starts from
        (default ``recon``).

    Returns
    -------
    recon : Reconstruction
        New ``markers``, ``fields`` (reach of ``markers − rest`` over the measured markers),
        ``similarity``; ``info["normalisation"]["scale"]`` 1 and ``info["rest"]`` the rest used.
    rest : (P, 3) float
    """
    from lipgen.recon.rereference import reference_similarity, renormalize
    from lipgen.recon.similarity import Similarity

    ref = reference_similarity(recon if reference is None else reference)
    names = physics.mesh.marker_names
    out = renormalize(recon, Similarity(1.0, ref.rotation, ref.translation), physics,
                      rest=(lambda X, m: quiet_rest(X, m, names=names)) if rest is None else rest)
    return out, np.asarray(out.info["rest"], dtype=np.float64)
