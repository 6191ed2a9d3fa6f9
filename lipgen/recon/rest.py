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
- **Rest from the recording** (:func:`recording_rest`). Speech pauses return the lips to rest, and
  the subject's rest differs from the model's by the subject's shape (2-3 mm per marker on the
  ``default`` preset), while a posture held as still as a pause lay 4-7 mm from rest on the seeds
  where the quietest frames failed (below). So the rest frames are the
  frames nearest the model's rest markers (:func:`rest_frames_near`: half of the larger of 10 and
  15 % of the frames), and the rest is each marker's median over its accepted sightings there.

Why not the quietest frames. The rule before 2026-12-05 took the densest half of the slowest 15 %
of the frames. A vowel held several times in a clip is slower and more often visited than its one
pause: on ``table51-pipeline`` subject seed 27 (80-seed report) its rest frames were one held
posture 6.9 mm RMS from the true rest (the clip's one pause, frames 110-116, comes within 0.6 mm of
it), and every displacement carried that posture. Chosen on validation subject seeds 100-119 of
``table51-pipeline`` (not its report's seeds), among 14 truth-free rules (slowness, stillness over
a window, nearness to the model's rest, clusters and mixtures of these; the scripts in
``renders/examples/table51_pipeline_rest/``): the rest against the subject's true rest, mm RMS over
the markers, mean / worst of 20 seeds, quietest frames -> nearest the model's rest (the model's rest
itself): training recordings (150 frames) 2.01 / 5.29 -> 1.55 / 2.71 (2.52 / 4.10); the utterance
(40 frames, its own) 3.72 / 7.38 -> 2.06 / 3.22; the other subject (40 frames) 3.47 / 7.35 ->
2.01 / 3.30 (2.75 / 5.02); with the true rest's frames (an oracle, for scale) 1.37, 2.11 and 2.03.
(The scripts' medians need 2 sightings of a marker; with :data:`MIN_SIGHTINGS` the training
recordings' figure is 1.60.)

It is biased towards the model's rest when small motions pass nearer the model's rest than the
subject's rest is: on a 32-frame synthetic clip whose syllables return to rest every 5 frames
(``tests/test_rest_source.py``), 0.54 mm RMS from the subject's shape after a rigid fit, where the
quiet frames gave 0.03 (the model's rest 1.58).

Scale 1, measured on the ``table51-pipeline`` recordings of subject seeds 7, 13 and 0 (preset
``default``, 640x480; the diagnosis seeds), normalised markers against the true model-frame marks
(mm RMS over the accepted sightings), the fitted scale -> scale 1: seed 7 training / utterance /
other subject 2.48 -> 1.85, 3.83 -> 3.17, 3.86 -> 2.63; seed 13 4.75 -> 3.94, 4.17 -> 3.31,
5.37 -> 1.24; seed 0 2.29 -> 1.92, 2.05 -> 1.52, 5.48 -> 4.03 (fitted scales 0.89-1.08).
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen._validate import as_float_array

__all__ = ["rest_frames_near", "recording_rest", "metric_renormalize", "measured_markers", "MIN_REST_FRAMES",
           "MIN_SIGHTINGS", "REST_SHARE"]

log = logging.getLogger(__name__)

MIN_REST_FRAMES = 10
"""A recording's rest frames are half of the larger of this and :data:`REST_SHARE` of its frames
(:func:`rest_frames_near`): 5 of 40 frames."""
REST_SHARE = 0.15
"""A recording's rest frames are half of this share of its frames (11 of 150), or of
:data:`MIN_REST_FRAMES`."""
MIN_SIGHTINGS = 1 / 3
"""Share of the rest frames a marker must be measured in for a rest of its own (:func:`recording_rest`)."""


def measured_markers(recon) -> np.ndarray:
    """(F, P) bool: the markers each frame's field reached (accepted and not a pose outlier)."""
    m = np.asarray(recon.visible, dtype=bool).copy()
    for f, j in recon.info.get("normalisation", {}).get("outliers", []):
        m[f, j] = False
    return m


def _markers_seen(markers, measured) -> tuple[np.ndarray, np.ndarray]:
    """``markers`` (F, P, 3) as floats and the (F, P) mask of those measured and finite."""
    X = as_float_array(markers, "markers", (None, None, 3), finite=False)
    m = np.asarray(measured, dtype=bool)
    if m.shape != X.shape[:2]:
        raise ValueError(f"measured must have shape {X.shape[:2]}, got {m.shape}")
    return X, m & np.all(np.isfinite(X), axis=-1)


def rest_frames_near(markers, measured, start, share: float = REST_SHARE,
                     min_frames: int = MIN_REST_FRAMES) -> np.ndarray:
    """The ``k = (max(min_frames, round(share · F)) + 1) // 2`` frames whose markers lie nearest ``start``.

    Parameters
    ----------
    markers : (F, P, 3) float
        Normalised markers (mm); NaN or unmeasured where not seen.
    measured : (F, P) bool
    start : (P, 3) float
        A posture near the subject's rest (the model's rest markers; NaN rows are left out).
    share : float
        In (0, 1].
    min_frames : int

    Returns
    -------
    (k,) int, sorted
        By the RMS distance over the markers measured in the frame (at least 3 of them; frames with
        fewer are never taken).
    """
    X, m = _markers_seen(markers, measured)
    S = as_float_array(start, "start", (X.shape[1], 3), finite=False)
    if not 0 < share <= 1:
        raise ValueError(f"share must be in (0, 1], got {share}")
    F = len(X)
    if F < 5:
        raise ValueError(f"need at least 5 frames to find the rest in, got {F}")
    m = m & np.all(np.isfinite(S), axis=-1)
    n = m.sum(axis=1)
    d2 = np.where(m, np.sum((np.where(m[..., None], X, 0.0) - np.nan_to_num(S)) ** 2, axis=-1), 0.0)
    dist = np.where(n >= 3, np.sqrt(d2.sum(axis=1) / np.maximum(n, 1)), np.inf)
    k = min(F, (max(int(min_frames), int(round(share * F)), 1) + 1) // 2)
    return np.sort(np.argsort(dist, kind="stable")[:k])


def recording_rest(markers, measured, start, share: float = REST_SHARE, min_frames: int = MIN_REST_FRAMES,
                   min_sightings: float = MIN_SIGHTINGS, names=None, return_frames: bool = False):
    """(P, 3) each marker's median position over the rest frames, mm; NaN where it cannot be told.

    Parameters
    ----------
    markers : (F, P, 3) float
        Normalised markers (mm), the frames of one recording (NaN where not measured).
    measured : (F, P) bool
        The accepted sightings (e.g. :func:`measured_markers`).
    start : (P, 3) float
        The model's rest markers: the rest frames are the recording's frames nearest it
        (:func:`rest_frames_near`).
    share, min_frames : float, int
        How many rest frames (:func:`rest_frames_near`).
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
        A marker seen in too few rest frames is NaN: its median over all frames would be pulled by
        the motion.
    """
    X, m = _markers_seen(markers, measured)
    P = X.shape[1]
    if not 0 <= min_sightings <= 1:
        raise ValueError(f"min_sightings must be a share in [0, 1], got {min_sightings}")
    if names is not None and len(names) != P:
        raise ValueError(f"names must name the {P} markers, got {len(names)}")
    q = rest_frames_near(X, m, start, share, min_frames)
    count = m[q].sum(axis=0)
    need = max(2, int(np.ceil(min_sightings * len(q))))
    out = np.full(X.shape[1:], np.nan)
    for j in np.flatnonzero(count >= need):
        out[j] = np.median(X[q[m[q, j]], j], axis=0)
    few = np.flatnonzero(count < need)
    if len(few):
        log.warning("rest from %d frames: %s measured in fewer than %d of them; the model's rest is "
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
        The subject's rest markers in the model frame (e.g. :func:`recording_rest` of the training
        recording; NaN rows: the model's). None: estimated from ``recon``'s own frames
        (:func:`recording_rest`; a marker seen in too few rest frames takes the model's rest).
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
    mesh = physics.mesh
    M = mesh.vertices[mesh.markers]

    def own_rest(X, m):
        return recording_rest(X, m, M, names=mesh.marker_names)

    out = renormalize(recon, Similarity(1.0, ref.rotation, ref.translation), physics,
                      rest=own_rest if rest is None else rest)
    return out, np.asarray(out.info["rest"], dtype=np.float64)
