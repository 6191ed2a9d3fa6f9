"""The "LipGen" tab in the 3D View sidebar (N panel)."""

from __future__ import annotations

import bpy


class _LipgenPanel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "LipGen"


def _wrapped(text: str, width: int = 48) -> list[str]:
    """Panel lines of a multi-line warning (labels do not wrap)."""
    import textwrap

    return [w for line in text.splitlines() for w in textwrap.wrap(line, width) or [""]]


def _lip_object(context):
    ob = context.active_object
    return ob if ob is not None and ob.type == "MESH" else None


class _SetUpLipsPanel(_LipgenPanel):
    """A sub-panel shown only for a mesh that LipGen has been set up on."""

    @classmethod
    def poll(cls, context):
        ob = _lip_object(context)
        return ob is not None and ob.lipgen.enabled


class VIEW3D_PT_lipgen(_LipgenPanel, bpy.types.Panel):
    bl_label = "LipGen"

    def draw(self, context):
        layout = self.layout
        op = layout.operator("object.lipgen_add_lips", icon="MESH_DATA")
        op.resolution = 0
        ob = _lip_object(context)
        if ob is None:
            layout.label(text="Select a mesh to use it with LipGen", icon="INFO")
        elif not ob.lipgen.enabled:
            layout.label(text=f"{ob.name}: not set up yet", icon="INFO")


class VIEW3D_PT_lipgen_physics(_LipgenPanel, bpy.types.Panel):
    bl_label = "Mesh & Physics"
    bl_parent_id = "VIEW3D_PT_lipgen"

    @classmethod
    def poll(cls, context):
        return _lip_object(context) is not None

    def draw(self, context):
        ob = _lip_object(context)
        s = ob.lipgen
        layout = self.layout
        col = layout.column(align=True)
        col.label(text="Vertex groups")
        col.prop_search(s, "anchors_group", ob, "vertex_groups")
        col.prop_search(s, "ridge_group", ob, "vertex_groups")
        col.prop_search(s, "strip_group", ob, "vertex_groups")
        col.prop_search(s, "skin_group", ob, "vertex_groups")
        col.prop_search(s, "markers_group", ob, "vertex_groups")
        col = layout.column(align=True)
        col.label(text="Stiffness (E)")
        col.prop(s, "stiffness_lip")
        col.prop(s, "stiffness_ridge")
        col.prop(s, "stiffness_strip")
        col.prop(s, "stiffness_skin")
        col.prop(s, "poisson")
        layout.prop(s, "unit_mm")
        row = layout.row(align=True)
        row.operator("object.lipgen_setup_mesh", icon="MOD_PHYSICS")
        row.operator("object.lipgen_build_physics", text="", icon="FILE_REFRESH")
        row.operator("object.lipgen_weld_cracks", text="", icon="AUTOMERGE_ON")
        if s.status:
            layout.label(text=s.status)
        if s.warnings:
            box = layout.box()
            for k, line in enumerate(_wrapped(s.warnings)):
                box.label(text=line, icon="ERROR" if k == 0 or line.startswith("- ") else "BLANK1")
        layout.label(text="Regions: a face joins a group's region only if all its vertices are in it",
                     icon="INFO")


class VIEW3D_PT_lipgen_modes(_SetUpLipsPanel, bpy.types.Panel):
    bl_label = "Modes"
    bl_parent_id = "VIEW3D_PT_lipgen"

    def draw(self, context):
        s = _lip_object(context).lipgen
        layout = self.layout
        row = layout.row(align=True)
        row.operator("object.lipgen_load_modes", text="Load", icon="FILEBROWSER")
        row.operator("object.lipgen_build_modes", text="From Physics", icon="MOD_PHYSICS")
        row.operator("object.lipgen_train_modes", text="Train", icon="LIGHTPROBE_VOLUME")
        if not len(s.modes):
            layout.label(text="No modes yet")
            return
        layout.label(text=f"{len(s.modes)} modes: {s.modes_source}")
        col = layout.column(align=True)
        for item in s.modes:
            col.prop(item, "value", text=item.name, slider=True)
        if any(kb.name == "LipGen Mean" for kb in (_lip_object(context).data.shape_keys.key_blocks
                                                   if _lip_object(context).data.shape_keys else ())):
            layout.prop(s, "mean_weight", slider=True)
        row = layout.row(align=True)
        row.operator("object.lipgen_key_modes", icon="KEY_HLT")
        row.operator("object.lipgen_import_curves", text="Import Curves", icon="IMPORT")
        layout.operator("object.lipgen_clear_modes", icon="X")


class VIEW3D_PT_lipgen_force(_SetUpLipsPanel, bpy.types.Panel):
    bl_label = "Force"
    bl_parent_id = "VIEW3D_PT_lipgen"

    def draw(self, context):
        ob = _lip_object(context)
        s = ob.lipgen
        layout = self.layout
        row = layout.row(align=True)
        row.prop_search(s, "force_group", ob, "vertex_groups", text="")
        op = row.operator("object.lipgen_assign_group", text="Use Selection", icon="RESTRICT_SELECT_OFF")
        op.group = s.force_group or "LipGen Force"
        op.role = "force_group"
        layout.prop(s, "force_use_normal")
        if not s.force_use_normal:
            layout.prop(s, "force_direction", text="")
        row = layout.row(align=True)
        row.prop(s, "force_magnitude")
        row.prop(s, "force_units", text="")
        layout.prop(s, "force_preview", toggle=True, icon="HIDE_OFF")
        if s.force_status:
            layout.label(text=s.force_status)
        row = layout.row(align=True)
        op = row.operator("object.lipgen_apply_force", text="Apply as Shape Key", icon="SHAPEKEY_DATA")
        op.result = "SHAPE_KEY"
        op = row.operator("object.lipgen_apply_force", text="Keyframe", icon="KEY_HLT")
        op.result = "KEYFRAME"
        box = layout.box()
        box.label(text="Reach: drag a few vertices, the rest follows")
        row = box.row(align=True)
        row.operator("object.lipgen_reach_start", icon="ADD")
        row.operator("object.lipgen_reach_solve", icon="CHECKMARK")
        box.operator("object.lipgen_reach_live", icon="PLAY")


class VIEW3D_PT_lipgen_output(_SetUpLipsPanel, bpy.types.Panel):
    bl_label = "Animation & Export"
    bl_parent_id = "VIEW3D_PT_lipgen"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        layout.operator("object.lipgen_import_curves", icon="IMPORT")
        layout.operator("object.lipgen_animate_visemes", icon="SOUND")
        layout.operator("object.lipgen_animate_audio", icon="SPEAKER")
        layout.operator("object.lipgen_export_usd", text="Export USD (lipgen)", icon="EXPORT")
        layout.label(text="File > Export > USD also writes the shape keys")


classes = (VIEW3D_PT_lipgen, VIEW3D_PT_lipgen_physics, VIEW3D_PT_lipgen_modes, VIEW3D_PT_lipgen_force,
           VIEW3D_PT_lipgen_output)
