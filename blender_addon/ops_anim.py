"""Operators that animate and export: coefficient curves as keyframes, USD export."""

from __future__ import annotations

from pathlib import Path

import bpy
import numpy as np
from bpy.props import EnumProperty, FloatProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from lipgen.addon import load_curves
from lipgen.addon.modebasis import SLIDER_LIMIT

from . import bridge, lipobject
from .lipobject import UserError
from .ops_common import LipgenOperator
from .ops_modes import _lipgen_object


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
        obj = _lipgen_object(context)
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


classes = (OBJECT_OT_lipgen_import_curves,)
