"""Where ``lipgen reconstruct`` measures displacements from: the model's rest or the recording's.

A field is the displacement of the lips from rest. Measured from the *model's* rest markers, a
subject whose lips have a shape of their own carries that shape difference as a constant
displacement in every frame (2-3 mm per marker on the ``default`` preset's subjects), and the
learned modes learn it as motion. A person reconstructing their own footage has no model rest
that is theirs. Three sources of the rest (``rest`` / ``rest_from`` of
:func:`measured_from_rest`):

- ``"recording"``: the recording's own rest (:func:`lipgen.recon.rest.recording_rest`: each
  marker's median over the frames nearest the model's rest), estimated on its **training
  frames only** (all but the held-out tail, as the normalisation's reference frame), at the rig's
  metric scale (:func:`lipgen.recon.rest.metric_renormalize`). A marker seen in too few rest frames
  takes the model's rest (a warning names it; ``info["rest_source"]["fallback"]``).
- ``rest_from``: another reconstruction's rest (one reconstructed with ``"recording"``), and its
  frame of reference: a test utterance measured from the training recording's rest, as the thesis
  measured all the data of its one subject from one rest.
- ``"model"``: the model's rest markers, at the scale of a similarity fitted on the most neutral
  training frame (the reconstruction as first built; on the ``easy`` preset the subject *is* the
  model, and this is exact).

The rest used is recorded in the reconstruction (``info["rest"]`` (P, 3) mm, ``info["rest_source"]``);
``lipgen train`` records it in the model's provenance and refuses a held-out tail that holds a rest
frame; ``lipgen evaluate`` measures the markers from it (:func:`rest_markers`).

The figures below were measured with the rest rule before 2026-12-05 (the densest half of the
quietest frames), not yet again with the frames nearest the model's rest (:mod:`lipgen.recon.rest`
has that rule's validation and held-out figures).

Validation (``lipgen generate --preset default --seed 1``, ``lipgen reconstruct --rest model``, then
the recording's rest as :func:`measured_from_rest` takes it; scored by
:func:`lipgen.evaluate.displacement.displacement_error`, the figures ``lipgen evaluate`` reports: the
marker displacements against the true ones, RMS / each marker's constant offset, mm, training frames
and the held-out tail):

- **150 frames** (10 calibration frames; subject seeds 44, 45; pauses at frames 59-63 and 91-94):
  from the model's rest -> from the recording's rest, seed 44 training 2.63 / 2.33 -> 1.58 / 0.99,
  tail 2.17 / 2.15 -> 0.73 / 0.61; seed 45 training 2.80 / 2.54 -> 2.01 / 1.66, tail
  2.11 / 2.17 -> 1.14 / 1.28 (rest frames from 2 and 3 pauses).
- **60 frames** (40 calibration frames; subject seed 40, two utterances): the training frames
  (0-49) hold no pause (the true displacement stays above 1.4 mm; the pause comes in the held-out
  tail), so the quietest frames are one held posture (frames 27-35; 22-26) and the recording's
  rest is worse: offsets 5.26 -> 6.05 and 2.82 -> 3.79 mm (training), and the second utterance
  measured from the first one's rest 2.01 -> 4.78 mm (tail). Hence :data:`MIN_PAUSES`: ``"auto"``
  takes the recording's rest only from rest frames of 2 or more pauses (these clips: 1 pause, so
  the model's rest).
- ``lipgen evaluate`` on subject seed 44 (150 frames; the test tail 140-149 is mostly a pause):
  Table 5.1, 10 modes vs the true surface, rows xyz / yz / xy, 1.51 / 1.13 / 1.80 -> 0.28 / 0.29 /
  0.45 mm² (relative 6.75 / 4.45 / 7.90 -> 1.15 / 1.08 / 1.89); physics 1.32 / 0.75 / 1.32 ->
  0.30 / 0.38 / 0.28 mm².

Held out, once, after the rule was frozen (subject seeds 50-52, 150 frames as above; rest frames
from 3 pauses each): training 2.89 / 2.71 -> 1.89 / 1.53, 3.85 / 3.65 -> 1.73 / 1.24,
3.18 / 2.94 -> 1.86 / 1.35; tail 2.65 / 2.66 -> 1.32 / 1.26, 3.20 / 3.19 -> 0.98 / 0.94,
2.69 / 2.70 -> 0.84 / 0.72. What is left once each marker's offset is taken out is unchanged
(1.2-1.4 mm training, 0.35-0.42 mm tail): the rest moves the constant part only. All these clips
share the motion seed 1 (the same speech timing), so their pauses fall on the same frames.

**Not for the** ``easy`` **preset.** Its motion is smooth random gestures, not speech: no pauses,
and its quietest frames are held gestures from 5 separate runs, which the pause rule takes for
pauses. On ``--preset easy --seed 46`` (150 frames), where the model's rest is the truth's, the
recording's rest made the offsets worse: training 0.67 -> 1.81 mm, tail 0.63 -> 1.79 mm. Such
data (and any subject with the model's shape) are measured with ``--rest model``. That is why the
default is the model's rest (:data:`DEFAULT_REST`; ``easy`` is ``lipgen generate``'s default preset and
must keep its figures), and ``"auto"`` (the pause rule) or ``"recording"`` is asked for by name.
With the rest frames nearest the model's rest (2026-12-05) the recording's rest no longer hurts
there: fresh ``--preset easy --seed 47`` / ``48`` (150 frames, ``--rest model`` -> ``--rest
recording``, RMS / each marker's offset, mm), training 0.98 / 0.43 -> 0.98 / 0.44 and
1.02 / 0.54 -> 1.03 / 0.57, tail 0.25 / 0.16 -> 0.24 / 0.13 and 1.06 / 0.96 -> 1.03 / 0.92
(script: ``renders/examples/table51_pipeline_rest/scripts/easy_disp.py``).
"""

from __future__ import annotations

import logging
import os

import numpy as np

from lipgen.errors import TopologyMismatchError
from lipgen.recon.rest import MIN_REST_FRAMES, metric_renormalize, recording_rest

__all__ = ["REST_CHOICES", "DEFAULT_REST", "PAUSE_GAP", "MIN_PAUSES", "pause_count", "check_rest_options",
           "rest_frames", "check_rest_from",
           "measured_from_rest", "rest_markers", "rest_frames_held_out", "rest_line"]

log = logging.getLogger(__name__)

REST_CHOICES = ("model", "recording", "auto")
"""The rests a reconstruction can be measured from (besides another reconstruction's, ``rest_from``):
the model's, the recording's, or ``auto``: the recording's when its rest frames come from
:data:`MIN_PAUSES` pauses and there are enough training frames, else the model's, saying why."""

DEFAULT_REST = "model"
"""The default of ``lipgen reconstruct --rest``. The model's rest, because ``auto`` takes the held
gestures of ``easy`` clips (the default preset of ``lipgen generate``) for pauses and measures them
worse (module docstring); for speech with pauses, ``auto`` or ``recording`` is better."""


PAUSE_GAP = 5
"""Rest frames more than this many frames apart belong to different pauses (:func:`pause_count`)."""

MIN_PAUSES = 2
"""Pauses ``auto`` needs among the rest frames to take the recording's rest."""


def pause_count(rest_frames) -> int:
    """How many separate pauses the rest frames (sorted ints) come from: runs split by gaps > PAUSE_GAP.

    The lips return to one rest in every pause, but a held posture can lie near the model's rest
    too: rest frames from one run alone may be a held posture, from two or more the same posture
    was returned to.
    """
    f = np.sort(np.asarray(rest_frames, dtype=np.int64))
    return 0 if len(f) == 0 else 1 + int(np.sum(np.diff(f) > PAUSE_GAP))


def check_rest_options(rest: str | None, rest_from=None) -> str:
    """The rest choice to use (``rest`` None: :data:`DEFAULT_REST`), one of :data:`REST_CHOICES`;
    ``ValueError`` naming a bad one.

    ``rest_from`` (a path) brings its own rest: any ``rest`` with it is refused.
    """
    if rest is not None and rest not in REST_CHOICES:
        raise ValueError(f"unknown rest {rest!r}; choose one of {', '.join(REST_CHOICES)} (or give "
                         "rest_from, another reconstruction)")
    if rest_from is not None and rest is not None:
        raise ValueError(f"rest {rest!r} (--rest) and rest_from {str(rest_from)!r} (--rest-from) contradict "
                         "each other: the rest of another recording is its own choice; give one of them")
    return DEFAULT_REST if rest is None else rest


def rest_frames(n_frames: int, test_frames: int | None = None, explicit: bool = True) -> np.ndarray | None:
    """(k,) int the training frames the recording's rest is estimated on (all but the held-out tail).

    Parameters
    ----------
    n_frames : int
    test_frames : int, optional
        The held-out tail (default :func:`lipgen.recon.split.default_test_frames`).
    explicit : bool
        The recording's rest was asked for: fewer than :data:`~lipgen.recon.rest.MIN_REST_FRAMES`
        training frames raise ``ValueError``. Else (``"auto"``) None is returned: the
        caller measures from the model's rest, and says so.
    """
    from lipgen.recon.split import training_candidates

    frames = training_candidates(n_frames, test_frames)
    if len(frames) >= MIN_REST_FRAMES:
        return frames
    if explicit:
        raise ValueError(f"the recording's rest needs at least {MIN_REST_FRAMES} training frames (before the "
                         f"held-out tail) to find the rest in, got {len(frames)} of {n_frames} frames; "
                         "record longer, hold out fewer (--test-frames), or measure from the model's rest "
                         "(--rest model) or another recording's (--rest-from)")
    return None


def check_rest_from(other, mesh, path="rest_from"):
    """``other``, a reconstruction whose rest another recording is to be measured from, checked.

    Parameters
    ----------
    other : Reconstruction
        Written by ``lipgen reconstruct --rest recording`` (e.g. ``Reconstruction.load(path)``).
    mesh : lipgen.LipMesh
        The model mesh of the recording to measure (the same markers, topology).
    path : str or os.PathLike
        Where ``other`` was read, for the messages.

    Returns
    -------
    Reconstruction
        ``other``; its ``info["rest"]`` is a finite (P, 3) rest, mm, model frame.
    """
    if other.info.get("topology_id") != mesh.topology_id or list(other.info.get("marker_names", [])) != list(
            mesh.marker_names):
        raise TopologyMismatchError(
            f"rest_from {str(path)!r} was reconstructed on mesh topology {other.info.get('topology_id')} "
            f"with markers {other.info.get('marker_names')}, not this model's ({mesh.topology_id}, "
            f"{list(mesh.marker_names)}); take the rest of a recording reconstructed with the same --mesh")
    kind = other.info.get("rest_source", {}).get("kind", "model")
    if kind != "recording" or "rest" not in other.info:
        raise ValueError(f"rest_from {str(path)!r} is measured from the model's rest (rest {kind!r}): it has "
                         "no recording rest to lend; reconstruct that recording with --rest recording")
    rest = np.asarray(other.info["rest"], dtype=np.float64)
    P = len(mesh.markers)
    if rest.shape != (P, 3) or not np.all(np.isfinite(rest)):
        raise ValueError(f"rest_from {str(path)!r}: its rest must be finite ({P}, 3) markers (mm), got shape "
                         f"{rest.shape}{'' if rest.shape != (P, 3) else ' with non-finite entries'}")
    return other


def measured_from_rest(recon, physics, rest: str = DEFAULT_REST, frames=None, rest_from=None,
                       rest_from_path=None, why: str | None = None, min_pauses: int = 0):
    """``recon`` with its markers and fields measured from the chosen rest (module docstring).

    Parameters
    ----------
    recon : Reconstruction
        As :func:`lipgen.recon.pipeline.reconstruct_dataset` builds it (model's rest, fitted scale).
    physics : lipgen.Physics
        Of the model mesh.
    rest : {"model", "recording", "auto"}
    frames : (k,) int, optional
        With ``"recording"``: the consecutive training frames the rest is estimated on (required).
    rest_from : Reconstruction, optional
        Another recording's (:func:`check_rest_from`): its rest and frame of reference are used.
    rest_from_path : str, optional
        Where ``rest_from`` was read, recorded as ``info["rest_from"]``.
    why : str, optional
        Recorded with ``"model"`` (e.g. why ``"auto"`` could not take the recording's rest).
    min_pauses : int
        With ``"recording"``: rest frames from fewer pauses (:func:`pause_count`) give the model's
        rest instead, and say why (``"auto"`` passes :data:`MIN_PAUSES`); 0: never.

    Returns
    -------
    Reconstruction
        ``info["rest"]`` (P, 3) mm the rest used and ``info["rest_source"]``: ``kind``, the first and
        last of the training ``frames`` it was estimated on, the ``rest_frames`` whose median it is,
        the markers that took the model's rest (``fallback``).
    """
    import dataclasses

    mesh = physics.mesh
    M = mesh.vertices[mesh.markers]
    if rest_from is not None:
        lent = np.asarray(rest_from.info["rest"])
        out, _ = metric_renormalize(recon, physics, rest=lent, reference=rest_from)
        src = dict(rest_from.info["rest_source"])
        source = {"kind": "recording", "of": "another recording", "frames": src.get("frames"),
                  "fallback": src.get("fallback", []), "dataset": rest_from.info.get("dataset")}
        info = {**_normalisation_kept(out, recon, f"the rotation of {rest_from.info.get('dataset')}"),
                "rest_source": source}
        if rest_from_path is not None:
            info["rest_from"] = os.path.abspath(rest_from_path)
        return dataclasses.replace(out, info=info)
    kind = check_rest_options(rest)
    if kind == "auto":  # the pause rule
        min_pauses = max(min_pauses, MIN_PAUSES)
    if kind == "model":
        source = {"kind": "model", "frames": None, "fallback": [], **({"why": why} if why else {})}
        return dataclasses.replace(recon, info={**recon.info, "rest": M.tolist(), "rest_source": source})
    if frames is None:
        raise ValueError("the recording's rest needs its training frames (frames=...)")
    frames = np.asarray(frames, dtype=np.int64)
    if len(frames) < MIN_REST_FRAMES or np.any(np.diff(frames) != 1):
        raise ValueError(f"the recording's rest needs at least {MIN_REST_FRAMES} consecutive training "
                         f"frames, got {len(frames)} frames {frames[:5].tolist()}...")
    names = mesh.marker_names
    estimate = {}

    def own_rest(X, m):
        estimate["rest"], estimate["at"] = recording_rest(X[frames], m[frames], M, names=names,
                                                          return_frames=True)
        return estimate["rest"]

    out, _ = metric_renormalize(recon, physics, rest=own_rest)
    at = [int(f) for f in frames[estimate["at"]]]
    pauses = pause_count(at)
    if pauses < min_pauses:
        reason = (f"the rest frames {at} (the training frames nearest the model's rest) are one stretch "
                  f"({pauses} pause), maybe a held posture, not a rest; record pauses, or give --rest "
                  f"recording or --rest-from")
        log.warning("%s: measured from the model's rest", reason)
        return measured_from_rest(recon, physics, "model", why=reason)
    if pauses < MIN_PAUSES:
        log.warning("the recording's rest is the median of frames %s, one stretch: if that is a held "
                    "posture, not a rest, measure from another recording's rest (--rest-from)", at)
    fallback = [names[j] for j in np.flatnonzero(~np.all(np.isfinite(estimate["rest"]), axis=1))]
    source = {"kind": "recording", "of": "this recording", "frames": [int(frames[0]), int(frames[-1])],
              "rest_frames": at, "pauses": pauses, "fallback": fallback}
    info = _normalisation_kept(out, recon, "its own reference frame's rotation")
    return dataclasses.replace(out, info={**info, "rest_source": source})


def _normalisation_kept(out, recon, reference: str) -> dict:
    """``out.info`` with the normalisation record of ``recon`` kept (its reference frame, fit), at
    scale 1 and with the reference that scale-1 frame came from."""
    norm = {**recon.info.get("normalisation", {}), "scale": 1.0, "fitted_scale":
            recon.info.get("normalisation", {}).get("scale"), "metric_reference": reference,
            "outliers": out.info["normalisation"]["outliers"],
            "borrowed_frames": out.info["normalisation"]["borrowed_frames"]}
    return {**out.info, "normalisation": norm}


def rest_markers(recon, mesh) -> np.ndarray:
    """(P, 3) float the rest markers ``recon``'s displacements are measured from, mm (model frame).

    ``info["rest"]`` when recorded, else (a reconstruction from before the choice) the model's.
    """
    M = mesh.vertices[mesh.markers]
    rest = recon.info.get("rest")
    if rest is None:
        return M.copy()
    rest = np.asarray(rest, dtype=np.float64)
    if rest.shape != M.shape:
        raise ValueError(f"the reconstruction's rest must be the ({len(M)}, 3) rest markers, got shape "
                         f"{rest.shape}")
    return np.where(np.isfinite(rest), rest, M)


def rest_frames_held_out(recon, held_out) -> list[int]:
    """The frames of ``recon``'s own rest (``--rest recording``) that are in ``held_out``
    (ints), sorted: held-out frames that shaped the training data (empty for any other rest)."""
    src = recon.info.get("rest_source", {})
    if src.get("of") != "this recording":
        return []
    return sorted(set(src.get("rest_frames", [])) & {int(f) for f in held_out})


def rest_line(recon) -> str:
    """One sentence: where ``recon``'s displacements are measured from."""
    src = recon.info.get("rest_source")
    if src is None or src.get("kind") == "model":
        why = "" if src is None or not src.get("why") else f" ({src['why']})"
        return f"the model's rest markers, at the scale fitted on the reference frame{why}"
    frames = src.get("frames")
    span = f"frames {frames[0]}-{frames[1]}" if frames else "its training frames"
    whose = ("this recording's" if src.get("of") == "this recording"
             else f"another recording's ({src.get('dataset')})")
    fallback = f"; the model's rest for {', '.join(src['fallback'])}" if src.get("fallback") else ""
    return f"{whose} rest (estimated on {span}), at the rig's metric scale{fallback}"
