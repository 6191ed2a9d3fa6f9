"""Lip sync: speech (audio and/or text) -> phones -> visemes -> activations -> mode coefficients.

The activations drive lipgen's synthetic subject (:mod:`lipgen.subject.motion`: muscle-like actions, a
jaw hinge, lip contact); its displacements on the model's nodes (the procedural meshes are
nested, node i of ``lip_mesh(r)`` is node i of every finer one) are projected onto the modes
of ``model`` (a fitted :class:`lipgen.modes.ModeModel`, e.g. from ``lipgen train``), or of the
default lips: ten modes learned from the subject's random gestures on ``lip_mesh(0)``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from lipgen.speech.audio import Audio
from lipgen.speech.decode import phones_from_audio
from lipgen.speech.phones import PhoneTrack, text_phones
from lipgen.speech.visemes import activations as viseme_dynamics
from lipgen.subject.activation import ACTIONS

__all__ = ["LipSync", "lipsync", "default_model", "model_mesh", "model_resolution", "performer",
           "project_activations"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class LipSync:
    """The result of :func:`lipsync`.

    Attributes
    ----------
    phones : PhoneTrack
        Phones with timings (s), and how they were found.
    fps : float
        Frames per second; frame ``f`` is at ``f / fps`` s of the audio.
    activations : (F, A) float
        Activations of :data:`lipgen.subject.activation.ACTIONS`.
    coefficients : (F, k) float
        Mode coefficients of ``model`` (mm, as ``ModeModel.synthesize`` takes them).
    model : ModeModel
        The modes.
    audio : Audio or None
        The speech, when the phones came from audio.
    text : str or None
        The transcript, if any.
    """

    phones: PhoneTrack
    fps: float
    activations: np.ndarray
    coefficients: np.ndarray
    model: object
    audio: Audio | None = None
    text: str | None = None

    @property
    def n_frames(self) -> int:
        return len(self.coefficients)

    @property
    def times(self) -> np.ndarray:
        """(F,) frame times (s)."""
        return np.arange(self.n_frames) / self.fps


@lru_cache(maxsize=2)
def performer(resolution: int = 1, seed: int = 0):
    """The synthetic subject on ``lip_mesh(max(resolution, 1))`` (cached, two kept)."""
    from lipgen.subject.motion import default_subject

    return default_subject(seed=int(seed), resolution=max(int(resolution), 1))


@lru_cache(maxsize=1)
def default_model():
    """Ten modes of ``lip_mesh(0)`` learned from 240 frames (8 s) of the synthetic subject's
    random gestures (seed 0), shipped precomputed (:mod:`lipgen.speech.defaults`)."""
    from lipgen.speech.defaults import load_default_lips

    return load_default_lips()[0]


@lru_cache(maxsize=8)
def model_mesh(resolution: int):
    """``lip_mesh(resolution)``; resolution 0 is read from the shipped default lips (the same
    mesh, tested), which spares the command building it (and importing scipy)."""
    if int(resolution) == 0:
        from lipgen.speech.defaults import load_default_lips

        return load_default_lips()[1]
    from lipgen.mesh.procedural import lip_mesh

    return lip_mesh(int(resolution))


@lru_cache(maxsize=8)
def _lips(resolution: int) -> tuple[int, str]:
    m = model_mesh(resolution)
    return m.n_nodes, m.topology_id


@lru_cache(maxsize=4)
def _node_motion(resolution: int, seed: int, n: int):
    """The subject's motion on the model's ``n`` nodes (the seed-0 default lips' is shipped)."""
    from lipgen.speech.defaults import load_default_lips, node_motion

    if int(resolution) == 0 and int(seed) == 0:
        motion = load_default_lips()[2]
        if motion.n_out == n:
            return motion
    return node_motion(performer(resolution, seed), n)


def model_resolution(model, max_resolution: int = 4) -> int:
    """The procedural lips resolution ``r`` that ``model`` was fitted on (``ValueError`` if none)."""
    for attr in ("mean_", "components_"):
        if not hasattr(model, attr):
            raise TypeError(f"model must be a fitted lipgen.modes.ModeModel (no {attr!r}); "
                            "use ModeModel.load() on a `lipgen train` model.npz")
    n = np.asarray(model.mean_).size // 3
    topo = getattr(model, "topology_id_", "")
    for r in range(max_resolution + 1):
        n_r, topo_r = _lips(r)
        if n_r == n and (not topo or topo == topo_r):
            return r
        if n_r > n:
            break
    raise ValueError(f"the model's mesh ({n} nodes, topology {topo or 'unknown'}) is not lipgen's "
                     "procedural lips: lip sync drives the synthetic subject, whose nodes are those "
                     "meshes' nodes; train the model on `lipgen generate` data of lip_mesh(r)")


def lipsync(audio: Audio | None = None, text: str | None = None, model=None, fps: float = 30.0,
            seed: int = 0, rate: float = 1.0) -> LipSync:
    """Animate lips from speech.

    Parameters
    ----------
    audio : Audio, optional
        Speech (:func:`lipgen.speech.read_wav`). With ``text``: forced alignment (falling back to
        recognition, with a warning, if the transcript does not fit); alone: phone recognition.
    text : str, optional
        English transcript; without ``audio`` the phones get Klatt-rule durations.
    model : ModeModel, optional
        Modes to project on (default :func:`default_model`).
    fps : float
        Output frame rate.
    seed : int
        Seed of the synthetic subject (its stiffness and gains).
    rate : float
        Speaking-rate factor for text alone.
    """
    if audio is None and text is None:
        raise ValueError("lip sync needs audio, a transcript, or both")
    fps = float(fps)
    if not np.isfinite(fps) or not 1.0 <= fps <= 1000.0:
        raise ValueError(f"fps must be between 1 and 1000, got {fps}")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be a whole number >= 0, got {seed!r}")
    if audio is not None and rate != 1.0:  # the recording sets its own pace
        raise ValueError(f"rate {rate} sets the pace of text alone; with audio the timing comes from the "
                         "recording: drop the rate (or the audio)")
    model = default_model() if model is None else model
    r = model_resolution(model)
    phones = phones_from_audio(audio, text) if audio is not None else text_phones(text, rate)
    n_frames = int(np.ceil((audio.duration if audio is not None else phones.duration) * fps)) + 1
    A = viseme_dynamics(phones, fps, n_frames)
    coef = project_activations(A, model, r, seed)
    return LipSync(phones, fps, A, coef, model, audio, text)


def project_activations(A: np.ndarray, model, resolution: int, seed: int = 0,
                        chunk: int = 512) -> np.ndarray:
    """(F, k) mode coefficients of the subject's motion for activations ``A`` (F, A).

    The motion of the model's nodes comes from :class:`lipgen.speech.defaults.NodeMotion`
    (equal to ``performer(resolution, seed).displacements(A)[:, :n]`` to round-off)."""
    if A.ndim != 2 or A.shape[1] != len(ACTIONS):
        raise ValueError(f"activations must have shape (F, {len(ACTIONS)}), got {A.shape}")
    n = np.asarray(model.mean_).size // 3
    motion = _node_motion(int(resolution), int(seed), n)
    out = [model.project(motion.displacements(A[i:i + chunk])) for i in range(0, len(A), chunk)]
    return np.concatenate(out)
