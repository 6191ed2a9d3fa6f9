"""Operators for forces and reach goals (thesis eq 4.3): the physics moves the rest of the lip."""

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

from lipgen.addon import moved_nodes, reach_goals

from . import bridge, lipobject, preview
from .lipobject import REACH_KEY, UserError
from .ops_common import LipgenOperator, lipgen_object

GOALS_GROUP = "LipGen Goals"
SOLVED_ATTR = "lipgen_reach_solved"
"""Point attribute: the reach key as last solved, to tell newly moved vertices from followers."""


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


class OBJECT_OT_lipgen_reach_start(LipgenOperator, bpy.types.Operator):
    """Start a reach edit: a fresh shape key to drag a few vertices on; Solve Reach moves the rest"""

    bl_idname = "object.lipgen_reach_start"
    bl_label = "New Reach Shape"

    name: StringProperty(name="Shape key", default=REACH_KEY)
    edit: BoolProperty(name="Enter Edit Mode", default=False, options={"SKIP_SAVE"})

    def invoke(self, context, event):
        self.edit = True
        return self.execute(context)

    def run(self, context):
        obj = lipgen_object(context)
        rest = bridge.rest_vertices(obj)
        kb = bridge.ensure_shape_key(obj, self.name, rest, (-10.0, 10.0))
        kb.value = 1.0
        bridge.remove_driver(kb)
        if obj.vertex_groups.get(GOALS_GROUP) is not None:
            obj.vertex_groups.remove(obj.vertex_groups[GOALS_GROUP])
        bridge.set_point_vectors(obj.data, SOLVED_ATTR, None)
        obj.active_shape_key_index = list(obj.data.shape_keys.key_blocks).index(kb)
        obj.data.update()
        if self.edit:
            bpy.ops.object.mode_set(mode="EDIT")


class OBJECT_OT_lipgen_reach_solve(LipgenOperator, bpy.types.Operator):
    """Solve the reach shape: moved vertices stay, the physics moves the rest with least strain (eq 4.3)"""

    bl_idname = "object.lipgen_reach_solve"
    bl_label = "Solve Reach"

    name: StringProperty(name="Shape key", default=REACH_KEY)
    threshold: FloatProperty(name="Moved by more than (mm)", default=1e-3, min=0.0, precision=4,
                             description="A vertex counts as moved (a goal) beyond this distance")
    hold_selected: BoolProperty(name="Hold selected", default=False,
                                description="Selected vertices that did not move stay in place")

    def run(self, context):
        obj = lipgen_object(context)
        keys = obj.data.shape_keys
        kb = None if keys is None else keys.key_blocks.get(self.name)
        if kb is None:
            raise UserError(f"no shape key {self.name!r}: press New Reach Shape, move a few "
                            "vertices of it in Edit Mode, then Solve Reach")
        unit = obj.lipgen.unit_mm
        rest = bridge.rest_vertices(obj)
        target = bridge.shape_key_co(kb)
        solved = bridge.point_vectors(obj.data, SOLVED_ATTR)
        baseline = rest if solved is None else solved
        goals = set(moved_nodes(baseline * unit, target * unit, self.threshold).tolist())
        if obj.vertex_groups.get(GOALS_GROUP) is not None:
            goals.update(bridge.vertex_group_nodes(obj, GOALS_GROUP).tolist())
        if self.hold_selected:
            goals.update(bridge.selected_vertices(obj.data).tolist())
        spec = lipobject.physics_spec(obj)
        phys = lipobject.physics_for_object(obj, spec)
        rg = reach_goals(rest * unit, target * unit, sorted(goals), spec.anchors)
        U, _F = phys.reach(rg.dofs, rg.values)
        new = rest + np.asarray(U) / unit
        bridge.set_shape_key_co(kb, new)
        bridge.set_point_vectors(obj.data, SOLVED_ATTR, new)
        bridge.set_vertex_group(obj, GOALS_GROUP, rg.nodes)
        obj.data.update()
        obj.update_tag()
        msg = f"{len(rg.nodes)} goal vertices, peak displacement {np.linalg.norm(U, axis=1).max():.3g} mm"
        if len(rg.skipped_anchors):
            msg += f"; {len(rg.skipped_anchors)} anchored vertices cannot move and were ignored"
            self.report({"WARNING"}, msg)
        else:
            self.report({"INFO"}, msg)


classes = (OBJECT_OT_lipgen_apply_force, OBJECT_OT_lipgen_reach_start, OBJECT_OT_lipgen_reach_solve)
