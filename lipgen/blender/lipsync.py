"""Speech for a rig: the data side of the add-on's "Animate from Audio" (no bpy here).

The speech's phones (:mod:`lipgen.speech`: PocketSphinx alignment with a transcript, or
recognition) become activations of the synthetic subject's actions, which the subject performs
on LipGen's procedural lips. A rig follows the performance through its modes:

- **LipGen's lips** (``lip_mesh(r)``, nested in the subject's mesh): each frame's displacement is
  projected on the modes (:meth:`ModeBasis.project`).
- **An artist's mesh** with modes and a markers group: the subject's marker displacements are
  matched to the rig's markers (by name when the rig stores LipGen's names, else, with 16
  markers, by position after centring and scaling both layouts, the rig in LipGen's axes: x
  across the mouth, y up, z out of the face) and the coefficients are the ridge least-squares
  fit of the modes at those markers (the LLSE idea of Basu 1997, eq 4.7, with a flat prior).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["SpeechAnimation", "speech_animation", "match_markers", "marker_coefficients"]


@dataclass(frozen=True, eq=False)
class SpeechAnimation:
    """Activations of a recording, and the performer's motion on demand.

    Attributes
    ----------
    activations : (F, A) float
        At ``fps``; frame ``f`` is at ``f / fps`` s of the audio.
    phones : lipgen.speech.PhoneTrack
    duration : float
        Seconds of audio.
    """

    activations: np.ndarray
    phones: object
    duration: float
    fps: float

    def displacements(self, n_nodes: int, seed: int = 0, chunk: int = 120,
                      progress: Callable[[float], None] | None = None) -> np.ndarray:
        """(F, n, 3) performer displacements (mm) on the first ``n_nodes`` nodes of its mesh."""
        from lipgen.speech.lipsync import performer

        subject = performer(1, seed)
        out = []
        for i in range(0, len(self.activations), chunk):
            out.append(subject.displacements(self.activations[i:i + chunk])[:, :n_nodes])
            if progress is not None:
                progress(min(1.0, (i + chunk) / len(self.activations)))
        return np.concatenate(out)


def speech_animation(wav_path: str, text: str | None, fps: float) -> SpeechAnimation:
    """Phones of ``wav_path`` (aligned to ``text`` if given) and their activations at ``fps``."""
    from lipgen.speech.audio import read_wav
    from lipgen.speech.decode import phones_from_audio
    from lipgen.speech.visemes import activations

    audio = read_wav(wav_path)
    phones = phones_from_audio(audio, text.strip() if text and text.strip() else None)
    n = int(np.ceil(audio.duration * fps)) + 1
    return SpeechAnimation(activations(phones, fps, n), phones, audio.duration, float(fps))


def match_markers(rig_points: np.ndarray, rig_names, lips_points: np.ndarray, lips_names) -> np.ndarray:
    """(m,) index into LipGen's markers of each rig marker (see the module doc).

    Raises ``ValueError`` when the rig's markers cannot be matched.
    """
    rig_points = np.asarray(rig_points, float)
    if rig_names:
        missing = [n for n in rig_names if n not in lips_names]
        if missing:
            raise ValueError(f"the rig's markers {missing} are not LipGen marker names")
        return np.array([list(lips_names).index(n) for n in rig_names])
    if len(rig_points) != len(lips_points):
        raise ValueError(f"the rig has {len(rig_points)} markers; following speech on an artist's mesh "
                         f"needs its markers group to hold LipGen's {len(lips_points)} markers")
    from scipy.optimize import linear_sum_assignment

    def norm(P):
        P = P - P.mean(axis=0)
        return P / np.sqrt((P**2).sum(axis=1).mean())

    cost = np.linalg.norm(norm(rig_points)[:, None] - norm(lips_points)[None], axis=2)
    _, col = linear_sum_assignment(cost)
    return col


def marker_coefficients(components: np.ndarray, mean: np.ndarray, rig_markers: np.ndarray,
                        targets: np.ndarray, ridge: float = 1e-3) -> np.ndarray:
    """(F, k) coefficients whose modes best give ``targets`` at the rig's markers.

    Parameters
    ----------
    components : (k, n, 3) float
        The rig's modes (mm per coefficient).
    mean : (n, 3) float
        The rig's mean displacement.
    rig_markers : (m,) int
        Marker nodes of the rig.
    targets : (F, m, 3) float
        Wanted marker displacements (mm).
    ridge : float
        Tikhonov weight relative to the largest squared singular value (keeps unobserved modes
        near zero).
    """
    B = components[:, rig_markers].reshape(len(components), -1).T  # (3m, k)
    y = (targets - mean[rig_markers]).reshape(len(targets), -1).T  # (3m, F)
    s_max = np.linalg.norm(B, 2) ** 2 if B.size else 1.0
    G = B.T @ B + ridge * s_max * np.eye(B.shape[1])
    return np.linalg.solve(G, B.T @ y).T
