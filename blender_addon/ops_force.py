"""The force operator: push chosen vertices, keep the physical response as a shape key."""

from __future__ import annotations

import bpy
import numpy as np
from bpy.props import (
    BoolProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    StringProperty,
)

from . import bridge, lipobject, preview
from .ops_common import LipgenOperator, lipgen_object


def _unique_key_name(obj, base: str) -> str:
    keys = obj.data.shape_keys
    if keys is None or keys.key_blocks.get(base) is None:
        return base
    i = 1
    while keys.key_blocks.get(f"{base}.{i:03d}") is not None:
        i += 1
    return f"{base}.{i:03d}"


class OBJECT_OT_lipgen_apply_force(LipgenOperator, bpy.types.Operator):
    """Push the chosen vertices with a force and keep the deformation as a shape key (or keyframe it)"""

    bl_idname = "object.lipgen_apply_force"
    bl_label = "Apply Force"

    group: StringProperty(name="Vertices", default="LipGen Force",
                          description="Vertex group of the vertices that receive the force")
    use_normal: BoolProperty(name="Along normals", default=False)
    direction: FloatVectorProperty(name="Direction", subtype="DIRECTION", size=3,
                                   default=(0.0, -1.0, 0.0), description="World-space direction")
    units: EnumProperty(
        name="Magnitude is", default="PEAK",
        items=(("PEAK", "Peak (mm)", "Largest vertex displacement, in mm"),
               ("FORCE", "Force", "Force on each chosen vertex, in the physics' units")))
    magnitude: FloatProperty(name="Magnitude", default=2.0, soft_min=-10.0, soft_max=10.0,
                             description="Peak displacement (mm) or force on each vertex")
    result: EnumProperty(
        name="Result", default="SHAPE_KEY",
        items=(("SHAPE_KEY", "Shape key", "A new shape key at value 1"),
               ("KEYFRAME", "Keyframed", "A new shape key whose value is keyframed 0 -> 1 -> 0 "
                "around the current frame")))
    name: StringProperty(name="Shape key", default="LipGen Force")
    ramp: IntProperty(name="Ramp frames", default=6, min=0,
                      description="Frames to blend in and out (Keyframed); 0 keys only the current frame")

    def invoke(self, context, event):
        s = context.active_object.lipgen
        self.group = s.force_group
        self.use_normal = s.force_use_normal
        self.direction = s.force_direction
        self.magnitude = s.force_magnitude
        self.units = s.force_units
        return self.execute(context)

    def run(self, context):
        obj = lipgen_object(context)
        U = preview.force_displacement(obj, self.group, self.magnitude, self.use_normal,
                                       self.direction, reuse=False, peak=self.units == "PEAK")
        if obj.lipgen.force_preview:
            obj.lipgen.force_preview = False  # removes the preview key
        name = _unique_key_name(obj, self.name)
        kb = lipobject.write_displacement_key(obj, name, U, 1.0)
        if self.result == "KEYFRAME":
            f = context.scene.frame_current
            frames, values = [f], [1.0]
            if self.ramp > 0:
                frames, values = [f - self.ramp, f, f + self.ramp], [0.0, 1.0, 0.0]
            fc = bridge.fcurve_ensure(kb.id_data, kb.path_from_id("value"))
            bridge.set_keyframes(fc, frames, values)
        obj.update_tag()
        self.report({"INFO"}, f"{name}: peak displacement {np.linalg.norm(U, axis=1).max():.3g} mm")


classes = (OBJECT_OT_lipgen_apply_force,)
