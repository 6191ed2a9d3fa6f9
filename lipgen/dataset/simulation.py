"""The subject's motion and what is true of it in each frame, before any rendering.

:func:`simulate_motion` runs the subject (:mod:`lipgen.subject`) for a dataset's settings, timed by
speech, a viseme script or random gestures; :func:`frame_truth` projects its marks through the rig
with their visibility. Both depend only on the settings, so every worker computes the same truth.
"""

from __future__ import annotations

import numpy as np

from lipgen.dataset.settings import GenerateSettings
from lipgen.rig.camera import VIEWS, MirrorRig
from lipgen.rig.imaging import on_mirror
from lipgen.rig.visibility import occluded
from lipgen.subject.face import FaceLook, FaceModel

__all__ = ["simulate_motion", "speech_phones", "frame_truth", "face_look"]

ACT_STREAM, HEAD_STREAM = 1, 2
"""Random streams of the dataset seed: the gestures and the head motion."""

def speech_phones(s: GenerateSettings):
    """The phones that time the motion and the 16 kHz audio of settings ``s``.

    Returns
    -------
    phones : lipgen.speech.PhoneTrack
    audio : (n,) float or None
        The recording (``s.speech``), or None where the phones come from text alone.
    """
    from lipgen.speech.audio import read_wav
    from lipgen.speech.decode import phones_from_audio
    from lipgen.speech.phones import text_phones

    if s.speech:
        audio = read_wav(s.speech)
        return phones_from_audio(audio, s.speech_text), audio
    return text_phones(s.speech_text), None


def simulate_motion(s: GenerateSettings, phones=None, progress: bool = False):
    """The subject's motion for settings ``s``.

    Parameters
    ----------
    s : GenerateSettings
    phones : lipgen.speech.PhoneTrack, optional
        Phones that time the motion (from :func:`speech_phones`).
    progress : bool
        A progress bar for the nonlinear truth physics (the only slow part).

    Returns
    -------
    lipgen.subject.motion.Motion
        Vertices, head poses and activations of ``s.frames`` frames.
    """
    from lipgen.subject import motion

    if phones is not None:
        from lipgen.speech.visemes import activations

        A = activations(phones, fps=s.fps, n_frames=s.frames)  # after the speech: back to rest
    elif s.script:
        A = motion.viseme_activations(s.script, fps=s.fps)
        A = A[np.arange(s.frames) % len(A)]  # the phrase is repeated to fill the frames
    else:
        A = motion.random_activations(s.frames, seed=np.random.default_rng([s.seed, ACT_STREAM]), fps=s.fps)
    head = motion.head_motion(s.frames, seed=np.random.default_rng([s.seed, HEAD_STREAM]), fps=s.fps,
                              max_rotation_deg=s.head_rotation_deg, max_translation_mm=s.head_translation_mm)
    subject = motion.default_subject(seed=s.seed, resolution=s.subject_resolution,
                                     subject_seed=s.subject_seed)
    if s.truth_physics == "layer":
        from lipgen.subject.truth import with_layer

        subject = with_layer(subject)
    if s.motion_sources == "independent":
        from lipgen.subject.independent import simulate_independent

        given = None if phones is None and not s.script else A  # else: its own speech and gestures
        return simulate_independent(subject, s.frames, np.random.default_rng([s.seed, ACT_STREAM]), head,
                                    s.fps, activations=given, progress=progress)
    return motion.simulate(subject, A, head, fps=s.fps, progress=progress)


def frame_truth(rig: MirrorRig, face: FaceModel, vertices: np.ndarray, pose: np.ndarray,
                mirror_extent=(0.0, 0.0)) -> dict:
    """Per-frame truth of the marks (16 markers then the nose) in both views.

    ``mirror_extent`` (half width, half height, mm; 0 for infinite): marks whose reflection the
    mirror's rectangle does not hold are not in the virtual view.

    Returns a dict of arrays named as :data:`lipgen.dataset.TRUTH_FIELDS` (views first).
    """
    X, N = face.marks(vertices, pose)
    surf = face.surfaces(vertices, pose)
    tris = face.occluders(surf)
    rims = face.dot_rims(surf)
    uv, depth, inside = rig.project(X)
    inside[0] &= on_mirror(rig, mirror_extent, X)
    k = len(X)
    occ, facing, frac = np.zeros((2, k), bool), np.zeros((2, k), bool), np.zeros((2, k))
    rim_pts = np.vstack([r[::2] for r in rims])  # every other rim point is plenty
    owner = np.repeat(np.arange(len(rims)), [len(r[::2]) for r in rims])
    queries = np.vstack([X, rim_pts])
    for v, cam in enumerate(rig.views):
        hidden = occluded(cam, queries, tris)  # one culling grid for the marks and their rims
        occ[v] = hidden[:k]
        facing[v] = np.sum((cam.center - X) * N, axis=1) > 0
        seen = cam.in_view(rim_pts) & ~hidden[k:]
        if v == 0:
            seen &= (rig.mirror_distance(rim_pts) > 0) & on_mirror(rig, mirror_extent, rim_pts)
        frac[v, : len(rims)] = np.bincount(owner, seen, len(rims)) / np.bincount(owner, minlength=len(rims))
        frac[v] *= facing[v]
    visible = inside & ~occ & facing
    uv_raw = np.stack([rig.to_raw(view, uv[v]) for v, view in enumerate(VIEWS)])
    return {"marks_world": X, "normals_world": N, "uv": uv, "uv_raw": uv_raw, "depth": depth,
            "in_image": inside, "occluded": occ, "facing": facing, "visible": visible,
            "dot_visible_fraction": frac}


def face_look(s: GenerateSettings) -> FaceLook:
    """The subject's :class:`~lipgen.subject.face.FaceLook` under settings ``s`` (seeded by ``s.seed``)."""
    c = s.conditions
    return FaceLook(dot_diameter=s.dot_diameter, texture=c.texture, texture_seed=s.seed, head=c.head,
                    head_mesh=c.head_mesh, mouth=c.mouth, dot_irregularity=c.ink, dot_smudge=c.smudge)
