"""LipGen for Blender: physically based lips driven by mode sliders, forces and reach goals.

A Blender 4.2+ extension (see ``blender_manifest.toml``). The computing is done by the
``lipgen`` package (bundled as a wheel), mostly through :mod:`lipgen.blender`; this package is the
thin bpy layer: properties on the Object, operators ``object.lipgen_*``, and the "LipGen"
sidebar tab. :mod:`.bridge` alone moves data between Blender and numpy.
"""

from __future__ import annotations

import bpy

from . import ops_anim, ops_export, ops_force, ops_mesh, ops_modes, ops_reach, panels, preview, properties

classes = (
    *properties.classes,
    *ops_mesh.classes,
    *ops_modes.classes,
    *ops_force.classes,
    *ops_reach.classes,
    *ops_anim.classes,
    *ops_export.classes,
    *panels.classes,
)


def _menu_add(self, context):
    self.layout.operator("object.lipgen_add_lips", text="LipGen Lips", icon="MESH_DATA")


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)
    properties.register_properties()
    bpy.types.VIEW3D_MT_mesh_add.append(_menu_add)


def unregister() -> None:
    from lipgen.blender import clear_physics_cache

    bpy.types.VIEW3D_MT_mesh_add.remove(_menu_add)
    properties.unregister_properties()
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
    preview.drop_sessions()
    clear_physics_cache()
