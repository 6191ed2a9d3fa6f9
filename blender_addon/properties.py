"""The settings and slider values LipGen keeps on each Object (``obj.lipgen``)."""

from __future__ import annotations

import bpy
from bpy.props import (
    BoolProperty,
    CollectionProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    StringProperty,
)

from lipgen.fem import DEFAULT_STIFFNESS

from . import preview
from .lipobject import GROUPS


def _tag(self, context) -> None:
    # Setting a property from Python does not re-evaluate drivers that read it; tag the object.
    self.id_data.update_tag()


class LIPGEN_PG_mode(bpy.types.PropertyGroup):
    """One mode slider. ``value`` drives the mode's shape key through a SUM driver."""

    name: StringProperty(name="Name")
    value: FloatProperty(
        name="Value", default=0.0, min=-10.0, max=10.0, soft_min=-3.0, soft_max=3.0, update=_tag,
        description="Mode amount in slider units (see Unit); keyframe it to animate")
    scale: FloatProperty(
        name="Unit", default=1.0, min=1e-12,
        description="The mode coefficient that a slider value of 1 stands for: one standard "
        "deviation for trained modes, a 1 mm peak for modes built from the physics")


def _stiffness(region: str, text: str):
    return FloatProperty(name=region.capitalize(), default=float(DEFAULT_STIFFNESS[region]),
                         min=1e-9, soft_min=1e-3, soft_max=100.0, description=text)


class LIPGEN_PG_settings(bpy.types.PropertyGroup):
    """LipGen state of one object: mesh roles, stiffness, mode sliders and the force tool."""

    enabled: BoolProperty(name="LipGen object", default=False)
    unit_mm: FloatProperty(
        name="mm per unit", default=1.0, min=1e-9, soft_max=1e4, precision=4,
        description="Millimetres per unit of the mesh's own coordinates (LipGen's lips: 1, "
        "a mesh modelled in metres: 1000)")
    anchors_group: StringProperty(
        name="Anchors", default=GROUPS["anchors"],
        description="Vertex group of the nodes fixed to the head (required)")
    markers_group: StringProperty(name="Markers", default="",
                                  description="Vertex group of the marker points (optional)")
    marker_order: StringProperty(default="", description="Marker vertices in marker order (LipGen's lips)")
    marker_names: StringProperty(default="", description="Marker names, comma separated")
    ridge_group: StringProperty(name="Ridge", default="",
                                description="Vertex group of the stiff inner ridge (optional)")
    strip_group: StringProperty(name="Strip", default="",
                                description="Vertex group of the soft strip into the mouth (optional)")
    skin_group: StringProperty(name="Skin", default="",
                               description="Vertex group of the skin around the lips (optional)")
    stiffness_lip: _stiffness("lip", "Young's modulus E of the lip surface")
    stiffness_ridge: _stiffness("ridge", "Young's modulus E of the inner ridge")
    stiffness_strip: _stiffness("strip", "Young's modulus E of the strip into the mouth")
    stiffness_skin: _stiffness("skin", "Young's modulus E of the skin around the lips")
    poisson: FloatProperty(name="Poisson ratio", default=0.01, min=0.0, max=0.49,
                           description="The thesis uses 0.01")
    topology_id: StringProperty(name="Topology", default="",
                                description="Topology id of the mesh when it was set up")
    status: StringProperty(name="Status", default="")
    warnings: StringProperty(name="Warnings", default="",
                             description="Set-up warnings (units, anchors), one per line")

    # Modes.
    modes: CollectionProperty(type=LIPGEN_PG_mode)
    active_mode: IntProperty(default=0)
    mean_weight: FloatProperty(
        name="Mean", default=1.0, min=0.0, max=1.0, update=_tag,
        description="Weight of the mean shape of trained modes (1 reproduces the model)")
    modes_source: StringProperty(name="Modes from", default="")
    modes_topology_id: StringProperty(default="")

    # Force tool (the preview updates live while these change).
    force_group: StringProperty(
        name="Vertices", default="LipGen Force", update=preview.update_settings,
        description="Vertex group of the vertices that receive the force")
    force_use_normal: BoolProperty(
        name="Along normals", default=False, update=preview.update,
        description="Push each vertex along its own normal instead of one direction")
    force_direction: FloatVectorProperty(
        name="Direction", subtype="DIRECTION", size=3, default=(0.0, -1.0, 0.0),
        update=preview.update, description="Force direction in world space")
    force_units: EnumProperty(
        name="Magnitude is", default="PEAK", update=preview.update,
        items=(("PEAK", "Peak (mm)", "The force is scaled so the largest vertex displacement is "
                "the magnitude, in mm"),
               ("FORCE", "Force", "The force on each chosen vertex, in the physics' units")))
    force_magnitude: FloatProperty(
        name="Magnitude", default=2.0, soft_min=-10.0, soft_max=10.0, update=preview.update,
        description="Peak displacement in mm, or the force on each vertex (see Magnitude is); "
        "negative pushes the other way")
    force_preview: BoolProperty(
        name="Live preview", default=False, update=preview.update_settings,
        description="Show the deformation as a shape key while the settings change")
    force_status: StringProperty(default="")


classes = (LIPGEN_PG_mode, LIPGEN_PG_settings)


def register_properties() -> None:
    bpy.types.Object.lipgen = bpy.props.PointerProperty(type=LIPGEN_PG_settings)


def unregister_properties() -> None:
    del bpy.types.Object.lipgen
