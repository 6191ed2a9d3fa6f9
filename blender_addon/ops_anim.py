"""Operators that animate and export: coefficient curves as keyframes, USD export."""

from __future__ import annotations

from pathlib import Path

import bpy
import numpy as np
from bpy.props import EnumProperty, FloatProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from lipgen.blender import load_curves
from lipgen.blender.modebasis import SLIDER_LIMIT

from . import bridge, lipobject
from .lipobject import UserError
from .ops_common import LipgenOperator, lipgen_object


def key_sliders(obj, frames: np.ndarray, sliders: np.ndarray) -> int:
    """Keyframe slider ``i`` at ``frames`` with column ``i`` of ``sliders``; returns clamped count."""
    clamped = int((np.abs(sliders) > SLIDER_LIMIT).sum())
    sliders = np.clip(sliders, -SLIDER_LIMIT, SLIDER_LIMIT)
    for i in range(sliders.shape[1]):
        fc = bridge.fcurve_ensure(obj, lipobject.slider_path(i))
        bridge.set_keyframes(fc, frames, sliders[:, i])
    obj.update_tag()
    return clamped


class OBJECT_OT_lipgen_import_curves(LipgenOperator, bpy.types.Operator, ImportHelper):
    """Keyframe the mode sliders from coefficient curves in an npz or CSV file"""

    bl_idname = "object.lipgen_import_curves"
    bl_label = "Import Coefficient Curves"

    filename_ext = ".npz"
    filter_glob: StringProperty(default="*.npz;*.csv", options={"HIDDEN"})
    start_frame: IntProperty(name="Start frame", default=1,
                             description="Frame of the first sample (files with times or no time base)")
    fps: FloatProperty(name="FPS", default=0.0, min=0.0,
                       description="Frames per second for files with times; 0 uses the scene's")
    units: EnumProperty(
        name="Values", default="COEFFICIENTS",
        items=(("COEFFICIENTS", "Mode coefficients", "As ModeModel.project / synthesize use them"),
               ("SLIDERS", "Slider values", "Already in slider units")))

    def invoke(self, context, event):
        self.start_frame = context.scene.frame_start
        return ImportHelper.invoke(self, context, event)

    def run(self, context):
        obj = lipgen_object(context)
        modes = obj.lipgen.modes
        if not len(modes):
            raise UserError("load or build modes before importing their curves")
        curves = load_curves(Path(bpy.path.abspath(self.filepath)))
        if curves.n_modes > len(modes):
            raise UserError(f"the file has {curves.n_modes} coefficient columns but "
                            f"{obj.name!r} has {len(modes)} modes; use a file made for these modes")
        scene = context.scene
        fps = self.fps or scene.render.fps / scene.render.fps_base
        frames = curves.frame_numbers(fps, self.start_frame)
        values = curves.coefficients
        if self.units == "COEFFICIENTS":
            values = values / np.array([m.scale for m in modes])[: curves.n_modes]
        clamped = key_sliders(obj, frames, values)
        msg = (f"keyed {curves.n_modes} sliders on {curves.n_samples} frames "
               f"({frames[0]:g}-{frames[-1]:g})")
        if clamped:
            self.report({"WARNING"}, f"{msg}; {clamped} value(s) beyond +-{SLIDER_LIMIT:g} slider "
                                     "units were clamped")
        else:
            self.report({"INFO"}, msg)


class OBJECT_OT_lipgen_animate_visemes(LipgenOperator, bpy.types.Operator):
    """Animate the mode sliders from a viseme script, performed by lipgen's synthetic subject"""

    bl_idname = "object.lipgen_animate_visemes"
    bl_label = "Animate from Visemes"

    script: StringProperty(
        name="Script", default="AA:0.3 EE:0.2 OO M:0.15 F REST:0.4",
        description="Visemes with optional durations in seconds (default 0.2), e.g. "
        "'AA:0.3 EE OO:0.25 M REST'; names: REST AA AE AH EH EE IH OH OO W M F TH S SH L R")
    start_frame: IntProperty(name="Start frame", default=1)
    coarticulation: FloatProperty(name="Coarticulation", default=0.2, min=0.0, max=1.0,
                                  description="Blend between neighbouring visemes (s)")

    def invoke(self, context, event):
        self.start_frame = context.scene.frame_current
        return context.window_manager.invoke_props_dialog(self, width=420)

    def run(self, context):
        from lipgen.blender.speech import speech_displacements

        obj = lipgen_object(context)
        if not len(obj.lipgen.modes):
            raise UserError("the sliders follow speech through modes: train modes from Speech "
                            "(Train > Speech) or load or build modes first")
        resolution = lipobject.lips_resolution_of(obj)
        scene = context.scene
        fps = scene.render.fps / scene.render.fps_base
        U = speech_displacements(self.script, fps, resolution, self.coarticulation)
        basis = lipobject.mode_basis(obj)
        coef = basis.project(U)
        frames = self.start_frame + np.arange(len(U), dtype=np.float64)
        clamped = key_sliders(obj, frames, basis.sliders(coef))
        if scene.frame_end < frames[-1]:
            scene.frame_end = int(frames[-1])
        miss = float(np.linalg.norm(basis.displacement(coef) - U, axis=2).max())
        msg = (f"keyed {len(U)} frames ({frames[0]:g}-{frames[-1]:g}); the modes follow the "
               f"performer within {miss:.2g} mm")
        self.report({"WARNING"} if clamped else {"INFO"},
                    msg + (f"; {clamped} slider values clamped to +-10" if clamped else ""))


class OBJECT_OT_lipgen_animate_audio(LipgenOperator, bpy.types.Operator, ImportHelper):
    """Animate the mode sliders from a speech recording (PocketSphinx phones, performed by
    lipgen's synthetic subject), and add the sound to the sequencer at the start frame"""

    bl_idname = "object.lipgen_animate_audio"
    bl_label = "Animate from Audio"

    filename_ext = ".wav"
    filter_glob: StringProperty(default="*.wav", options={"HIDDEN"})
    transcript: StringProperty(
        name="Transcript", default="",
        description="What is said, in English (optional): aligned to the audio for accurate timing; "
        "without it the phones are recognised")
    start_frame: IntProperty(name="Start frame", default=1, description="Frame where the audio starts")
    add_sound: bpy.props.BoolProperty(name="Add sound to the sequencer", default=True)

    def invoke(self, context, event):
        self.start_frame = context.scene.frame_current
        return ImportHelper.invoke(self, context, event)

    def run(self, context):
        from lipgen.blender.lipsync import marker_coefficients, match_markers, speech_animation
        from lipgen.mesh.procedural import lip_mesh

        obj = lipgen_object(context)
        if not len(obj.lipgen.modes):
            raise UserError("the sliders follow speech through modes: train modes from Speech "
                            "(Train > Speech) or load or build modes first")
        path = Path(bpy.path.abspath(self.filepath))
        if not path.is_file():
            raise UserError(f"sound file not found: {path}")
        basis = lipobject.mode_basis(obj)
        try:  # LipGen's lips follow node for node; another mesh through its markers
            resolution, markers = lipobject.lips_resolution_of(obj), None
        except UserError:
            resolution = None
            markers, names = lipobject.markers_of(obj)
            if len(markers) < 3:
                raise UserError(f"{obj.name!r} is not LipGen's lips and has no markers group: give it "
                                "LipGen's 16 markers (Set Up Physics > Markers) to follow speech") from None
        scene = context.scene
        fps = scene.render.fps / scene.render.fps_base
        wm = context.window_manager
        wm.progress_begin(0, 100)
        try:
            anim = speech_animation(str(path), self.transcript, fps)  # checks the file and the text
            wm.progress_update(30)
            if markers is None:
                U = anim.displacements(lip_mesh(resolution).n_nodes,
                                       progress=lambda f: wm.progress_update(30 + int(60 * f)))
                coef = basis.project(U)
            else:
                lm = lip_mesh(1)
                idx = match_markers(bridge.rest_vertices(obj)[markers] * obj.lipgen.unit_mm, names,
                                    lm.vertices[lm.markers], lm.marker_names)
                U = anim.displacements(lm.n_nodes, progress=lambda f: wm.progress_update(30 + int(60 * f)))
                coef = marker_coefficients(basis.components, basis.mean, markers, U[:, lm.markers[idx]])
        finally:
            wm.progress_end()
        frames = self.start_frame + np.arange(len(coef), dtype=np.float64)
        clamped = key_sliders(obj, frames, basis.sliders(coef))
        if scene.frame_end < frames[-1]:
            scene.frame_end = int(frames[-1])
        if self.add_sound:
            editor = scene.sequence_editor or scene.sequence_editor_create()
            strips = editor.strips if hasattr(editor, "strips") else editor.sequences  # 5.x / 4.x
            channel = 1 + max((st.channel for st in strips), default=0)
            strips.new_sound(path.stem, str(path), channel, int(self.start_frame))
        ph = anim.phones
        how = (f"aligned to the transcript (confidence {ph.confidence:.2f})" if ph.source == "alignment"
               else "recognised")
        msg = (f"keyed {len(coef)} frames ({frames[0]:g}-{frames[-1]:g}) from "
               f"{sum(p != 'SIL' for p in ph.labels)} phones {how}")
        self.report({"WARNING"} if clamped else {"INFO"},
                    msg + (f"; {clamped} slider values clamped to +-10" if clamped else ""))


classes = (OBJECT_OT_lipgen_import_curves, OBJECT_OT_lipgen_animate_visemes, OBJECT_OT_lipgen_animate_audio)
