"""Blender-side checks of "Animate from Audio" (run in the bpy worker; see test_blender_speech.py)."""

from __future__ import annotations

import bpy
import numpy as np
from bpy_checks_addon import _sheet, add_lips, call_error, evaluated, fresh, set_group

from lipgen.mesh.procedural import lip_mesh
from lipgen.modes.model import ModeModel


def _strips(scene):
    ed = scene.sequence_editor
    if ed is None:
        return []
    return list(ed.strips if hasattr(ed, "strips") else ed.sequences)


def check_audio_on_lips(wav: str, text: str) -> dict:
    """Every keyed frame equals the core's ModeModel.synthesize(project(performer's displacement))
    for the same phones; the sound strip starts at the start frame; undo removes both."""
    from lipgen.speech.audio import read_wav
    from lipgen.speech.decode import phones_from_audio
    from lipgen.speech.lipsync import performer
    from lipgen.speech.visemes import activations
    from lipgen.subject.activation import random_activations

    fresh()
    obj = add_lips(0)
    name = obj.name
    assert bpy.ops.object.lipgen_train_modes(source="SPEECH", n_modes=8) == {"FINISHED"}
    scene = bpy.context.scene
    bpy.ops.ed.undo_push(message="before audio")
    assert bpy.ops.object.lipgen_animate_audio("EXEC_DEFAULT", True, filepath=wav, transcript=text,
                                               start_frame=7) == {"FINISHED"}
    strips = _strips(scene)
    # The core, independently of the add-on's code path.
    lm = lip_mesh(0)
    n = lm.n_nodes
    subject = performer(1, 0)
    model = ModeModel(8).fit(subject.displacements(random_activations(240, seed=0, fps=30.0))[:, :n], mesh=lm)
    fps = scene.render.fps / scene.render.fps_base
    audio = read_wav(wav)
    phones = phones_from_audio(audio, text)
    A = activations(phones, fps, int(np.ceil(audio.duration * fps)) + 1)
    U = subject.displacements(A)[:, :n]
    devs = []
    for i in range(0, len(U), 4):
        scene.frame_set(7 + i)
        want = model.synthesize(model.project(U[i]))
        devs.append(float(np.abs(evaluated(obj) - lm.vertices - want).max()))
    out = {"max_dev_mm": max(devs), "frames": len(U), "peak_mm": float(np.abs(U).max()),
           "strips": [(s.type, int(s.frame_start), bpy.path.abspath(s.sound.filepath)) for s in strips],
           "frame_end": scene.frame_end, "phone_source": phones.source}
    bpy.ops.ed.undo()
    obj = bpy.data.objects[name]
    out["strips_after_undo"] = len(_strips(bpy.context.scene))
    ad = obj.animation_data
    out["action_after_undo"] = None if ad is None or ad.action is None else ad.action.name
    out["missing_file"] = call_error(bpy.ops.object.lipgen_animate_audio, filepath=wav + ".nope")
    return out


def check_audio_on_artist_mesh(wav: str, text: str) -> dict:
    """An artist's sheet with physics modes and 16 markers follows the performer's markers: its
    keyed coefficients are the core's ridge fit of its modes at its markers."""
    from blender_addon import bridge, lipobject
    from lipgen.blender.lipsync import marker_coefficients, match_markers, speech_animation

    fresh()
    obj = _sheet("ArtistLips", nx=12, ny=8)
    V = np.array([v.co for v in obj.data.vertices])
    set_group(obj, "LipGen Anchors", np.flatnonzero(V[:, 1] < V[:, 1].min() + 1e-6))
    mouth = np.flatnonzero((np.abs(V[:, 1]) < 0.0075) & (np.abs(V[:, 0]) < 0.017))
    rng = np.random.default_rng(0)
    markers = np.sort(rng.choice(mouth, 16, replace=False))
    set_group(obj, "Markers", markers)
    obj.lipgen.markers_group = "Markers"
    assert bpy.ops.object.lipgen_setup_mesh() == {"FINISHED"}
    obj.lipgen.markers_group = "Markers"
    assert bpy.ops.object.lipgen_build_modes(n_modes=6) == {"FINISHED"}
    none = _sheet("NoMarkers")
    V2 = np.array([v.co for v in none.data.vertices])
    set_group(none, "LipGen Anchors", np.flatnonzero(V2[:, 1] < V2[:, 1].min() + 1e-6))
    assert bpy.ops.object.lipgen_setup_mesh() == {"FINISHED"}
    assert bpy.ops.object.lipgen_build_modes(n_modes=2) == {"FINISHED"}
    refusal = call_error(bpy.ops.object.lipgen_animate_audio, filepath=wav, transcript=text)
    bpy.context.view_layer.objects.active = obj
    assert bpy.ops.object.lipgen_animate_audio(filepath=wav, transcript=text, start_frame=1,
                                               add_sound=False) == {"FINISHED"}
    basis = lipobject.mode_basis(obj)
    scene = bpy.context.scene
    anim = speech_animation(wav, text, scene.render.fps / scene.render.fps_base)
    lm = lip_mesh(1)
    nodes, names = lipobject.markers_of(obj)
    idx = match_markers(bridge.rest_vertices(obj)[nodes] * obj.lipgen.unit_mm, names,
                        lm.vertices[lm.markers], lm.marker_names)
    U = anim.displacements(lm.n_nodes)
    coef = marker_coefficients(basis.components, basis.mean, nodes, U[:, lm.markers[idx]])
    devs = []
    for i in range(0, len(coef), 5):
        scene.frame_set(1 + i)
        got = np.array([m.value for m in obj.lipgen.modes])
        devs.append(float(np.abs(got - basis.sliders(coef[i])).max()))
    moved = float(np.abs(basis.displacement(coef) - basis.mean).max())
    return {"max_slider_dev": max(devs), "moved_mm": moved, "refusal": refusal,
            "matched": sorted(idx.tolist())}
