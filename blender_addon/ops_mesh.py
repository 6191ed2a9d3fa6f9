"""Operators that make a LipGen object: add our lips, or set up the artist's own mesh."""

from __future__ import annotations

import math
import time

import bpy
import numpy as np
from bpy.props import FloatProperty, IntProperty, StringProperty

from lipgen.mesh.lipmesh import REGIONS

from . import bridge, lipobject, preview
from .lipobject import GROUPS, REGION_ATTR, UserError
from .ops_common import LipgenOperator, active_mesh


def _describe(phys, seconds: float) -> str:
    m = phys.mesh
    return (f"physics ready: {m.n_nodes} nodes, {m.n_faces} triangles, {len(m.anchors)} anchors "
            f"({seconds:.2f} s)")


class OBJECT_OT_lipgen_add_lips(LipgenOperator, bpy.types.Operator):
    """Add LipGen's procedural lips, with anchors, ridge, strip, skin and markers as vertex groups"""

    bl_idname = "object.lipgen_add_lips"
    bl_label = "Add LipGen Lips"
    needs_mesh = False

    resolution: IntProperty(
        name="Resolution", default=0, min=0, max=4,
        description="0 is the thesis's mesh (about 200 nodes); each step has about 4x the faces")

    @classmethod
    def poll(cls, context):
        return context.mode == "OBJECT"

    def run(self, context):
        from lipgen import lip_mesh

        lm = lip_mesh(self.resolution)
        me = bridge.new_mesh("LipGen Lips", lm.vertices, lm.faces)
        codes = np.array([REGIONS.index(lm.region_names[r]) if lm.region_names[r] in REGIONS else 0
                          for r in range(len(lm.region_names))], np.int64)[lm.regions]
        bridge.set_face_attribute(me, REGION_ATTR, codes)
        obj = bpy.data.objects.new("LipGen Lips", me)
        context.collection.objects.link(obj)
        # Mesh data stays in the model frame and millimetres (so it matches lipgen bit for bit);
        # the object turns it upright (+y up -> +Z up, +z out of the face -> -Y) at real size.
        obj.rotation_euler = (math.pi / 2, 0.0, 0.0)
        obj.scale = (0.001, 0.001, 0.001)
        obj.location = context.scene.cursor.location
        bridge.set_vertex_group(obj, GROUPS["anchors"], lm.anchors)
        bridge.set_vertex_group(obj, GROUPS["markers"], lm.markers)
        for region in ("ridge", "strip", "skin"):
            if region in lm.region_names:
                bridge.set_vertex_group(obj, GROUPS[region], lm.region_nodes(region))
        bridge.ensure_basis(obj)
        s = obj.lipgen
        s.enabled = True
        s.unit_mm = 1.0
        s.anchors_group = GROUPS["anchors"]
        s.markers_group = GROUPS["markers"]
        s.ridge_group = GROUPS["ridge"]
        s.strip_group = GROUPS["strip"]
        s.skin_group = GROUPS["skin"] if "skin" in lm.region_names else ""
        s.topology_id = lm.topology_id
        s.marker_order = ",".join(str(int(i)) for i in lm.markers)
        s.marker_names = ",".join(lm.marker_names)
        for o in context.view_layer.objects:
            o.select_set(False)
        obj.select_set(True)
        context.view_layer.objects.active = obj
        self.report({"INFO"}, f"added lips: {lm.n_nodes} vertices, {lm.n_faces} faces, "
                              f"{len(lm.markers)} markers")


class OBJECT_OT_lipgen_setup_mesh(LipgenOperator, bpy.types.Operator):
    """Use this mesh with LipGen: read the region vertex groups, check the mesh and build its physics"""

    bl_idname = "object.lipgen_setup_mesh"
    bl_label = "Set Up Physics"

    unit_mm: FloatProperty(
        name="mm per unit", default=0.0, min=0.0,
        description="Millimetres per mesh unit; 0 derives it from the scene unit scale and the "
        "object scale")

    def run(self, context):
        obj = active_mesh(context)
        s = obj.lipgen
        if self.unit_mm > 0:
            unit = self.unit_mm
        elif s.enabled:
            unit = s.unit_mm
        else:
            scale = float(np.mean(np.abs(np.array(obj.matrix_world.to_scale()))))
            unit = 1000.0 * context.scene.unit_settings.scale_length * scale
        groups = {"ridge": s.ridge_group, "strip": s.strip_group, "skin": s.skin_group}
        codes = lipobject.region_codes_from_groups(obj, groups)
        # Check everything (groups, mesh, grounding) before changing the object.
        old_unit = s.unit_mm
        old_codes = bridge.face_attribute(obj.data, REGION_ATTR)
        s.unit_mm = unit
        bridge.set_face_attribute(obj.data, REGION_ATTR, codes)
        t0 = time.perf_counter()
        try:
            phys = lipobject.physics(obj)
        except BaseException:
            s.unit_mm = old_unit
            if old_codes is None:
                obj.data.attributes.remove(obj.data.attributes[REGION_ATTR])
            else:
                bridge.set_face_attribute(obj.data, REGION_ATTR, old_codes)
            raise
        bridge.ensure_basis(obj)
        s.enabled = True
        s.topology_id = phys.mesh.topology_id
        s.status = _describe(phys, time.perf_counter() - t0)
        preview.drop_sessions(obj)
        counts = {r: int((codes == REGIONS.index(r)).sum()) for r in REGIONS}
        self.report({"INFO"}, f"{s.status}; faces per region {counts}")


class OBJECT_OT_lipgen_build_physics(LipgenOperator, bpy.types.Operator):
    """Build (or check) the physics of the active LipGen object with its current stiffness"""

    bl_idname = "object.lipgen_build_physics"
    bl_label = "Build Physics"

    def run(self, context):
        obj = active_mesh(context)
        t0 = time.perf_counter()
        phys = lipobject.physics(obj)
        obj.lipgen.status = _describe(phys, time.perf_counter() - t0)
        self.report({"INFO"}, obj.lipgen.status)


class OBJECT_OT_lipgen_assign_group(LipgenOperator, bpy.types.Operator):
    """Put the selected vertices in a LipGen vertex group (anchors, force vertices, ...)"""

    bl_idname = "object.lipgen_assign_group"
    bl_label = "Use Selection"

    group: StringProperty(name="Vertex group", default="LipGen Force")
    role: StringProperty(name="Setting", default="force_group",
                         description="Which LipGen setting names the group")

    def run(self, context):
        obj = active_mesh(context)
        nodes = bridge.selected_vertices(obj.data)
        if len(nodes) == 0:
            raise UserError("no vertex is selected; select vertices in Edit Mode first")
        allowed = ("force_group", "anchors_group", "markers_group", "ridge_group", "strip_group",
                   "skin_group")
        if self.role not in allowed:
            raise UserError(f"role must be one of {allowed}, got {self.role!r}")
        bridge.set_vertex_group(obj, self.group, nodes)
        preview.drop_sessions(obj)
        setattr(obj.lipgen, self.role, self.group)
        self.report({"INFO"}, f"{len(nodes)} vertices in {self.group!r}")


classes = (OBJECT_OT_lipgen_add_lips, OBJECT_OT_lipgen_setup_mesh, OBJECT_OT_lipgen_build_physics,
           OBJECT_OT_lipgen_assign_group)
