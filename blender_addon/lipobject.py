"""A LipGen object: its physics, its modes, and the shape keys that carry them.

This is the glue between an Object's settings (``obj.lipgen``) and :mod:`lipgen.blender`. Data
crosses between Blender and numpy only through :mod:`.bridge`. Lengths: the mesh stores its
own units; ``settings.unit_mm`` converts them to the millimetres of the physics.
"""

from __future__ import annotations

import re

import numpy as np

from lipgen.blender import ModeBasis, PhysicsSpec, physics_for
from lipgen.blender.modebasis import SLIDER_LIMIT
from lipgen.errors import MeshError
from lipgen.mesh.lipmesh import REGIONS, LipMesh

from . import bridge

__all__ = [
    "REGION_ATTR", "MEAN_KEY", "PREVIEW_KEY", "REACH_KEY", "GROUPS", "UserError",
    "mesh_object", "regions_per_triangle", "region_codes_from_groups", "physics_spec", "physics",
    "physics_for_object", "lip_mesh_of", "markers_of", "topology_id", "lips_resolution_of",
    "apply_mode_basis", "mode_basis", "clear_modes", "mode_key_name", "write_displacement_key", "slider_path",
]

REGION_ATTR = "lipgen_region"
"""Integer face attribute: region code per polygon, an index into lipgen.mesh.REGIONS."""
MEAN_KEY = "LipGen Mean"
PREVIEW_KEY = "LipGen Preview"
REACH_KEY = "LipGen Reach"
GROUPS = {"anchors": "LipGen Anchors", "markers": "LipGen Markers", "ridge": "LipGen Ridge",
          "strip": "LipGen Strip", "skin": "LipGen Skin"}
"""Default vertex-group names."""


class UserError(Exception):
    """A problem the artist can fix; operators report its message as an error."""


def mesh_object(obj):
    """``obj`` if it is a mesh object in Object Mode, else :class:`UserError`."""
    if obj is None or obj.type != "MESH":
        raise UserError("select a mesh object first")
    if obj.mode != "OBJECT":
        obj.update_from_editmode()
    return obj


def slider_path(i: int) -> str:
    return f"lipgen.modes[{i}].value"


def mode_key_name(name: str) -> str:
    return f"LipGen {name}"


# ---- physics ------------------------------------------------------------------------------
def regions_per_triangle(obj, poly_index: np.ndarray) -> np.ndarray:
    """Region code of each triangle, from the polygon attribute (all "lip" if absent)."""
    codes = bridge.face_attribute(obj.data, REGION_ATTR)
    if codes is None:
        return np.zeros(len(poly_index), np.int64)
    bad = (codes < 0) | (codes >= len(REGIONS))
    if bad.any():
        raise UserError(f"face attribute {REGION_ATTR!r} has code {int(codes[bad][0])} on "
                        f"{int(bad.sum())} face(s); codes must be 0..{len(REGIONS) - 1} for {REGIONS}")
    return codes[poly_index]


def region_codes_from_groups(obj, groups: dict[str, str]) -> np.ndarray:
    """(p,) region code per polygon: a polygon whose vertices are all in a region's vertex
    group gets that region (strip before ridge before skin); the rest are "lip"."""
    me = obj.data
    loop_vert, loop_start = bridge.polygon_loops(me)
    codes = np.zeros(len(me.polygons), np.int64)
    for region in ("skin", "ridge", "strip"):  # later wins
        name = groups.get(region, "")
        if not name:
            continue
        if obj.vertex_groups.get(name) is None:
            raise UserError(f"the {region} vertex group {name!r} does not exist on {obj.name!r}")
        mask = np.zeros(len(me.vertices), bool)
        mask[bridge.vertex_group_nodes(obj, name)] = True
        inside = np.minimum.reduceat(mask[loop_vert].astype(np.int8), loop_start).astype(bool)
        codes[inside] = REGIONS.index(region)
    return codes


def _group_nodes(obj, name: str, role: str, required: bool) -> np.ndarray:
    if not name:
        if required:
            raise UserError(f"choose the vertex group of the {role} in the LipGen panel")
        return np.zeros(0, np.int64)
    if obj.vertex_groups.get(name) is None:
        raise UserError(f"the {role} vertex group {name!r} does not exist on {obj.name!r}; "
                        "create it or pick another in the LipGen panel")
    nodes = bridge.vertex_group_nodes(obj, name)
    if required and len(nodes) == 0:
        raise UserError(f"the {role} vertex group {name!r} is empty; assign the vertices that "
                        "are fixed to the head (e.g. the far edge of the strip into the mouth)")
    return nodes


def physics_spec(obj) -> PhysicsSpec:
    """What the physics of ``obj`` depends on, read from its rest shape and settings."""
    s = obj.lipgen
    tris, poly = bridge.mesh_triangles(obj.data)
    if len(tris) == 0:
        raise UserError(f"{obj.name!r} has no faces; the physics needs a surface of triangles")
    stiffness = (("lip", s.stiffness_lip), ("ridge", s.stiffness_ridge),
                 ("strip", s.stiffness_strip), ("skin", s.stiffness_skin))
    return PhysicsSpec(
        vertices=bridge.rest_vertices(obj) * s.unit_mm, faces=tris,
        regions=regions_per_triangle(obj, poly),
        anchors=_group_nodes(obj, s.anchors_group, "anchors", required=True),
        stiffness=stiffness, poisson=s.poisson,
        markers=_group_nodes(obj, s.markers_group, "markers", required=False), name=obj.name)


def physics(obj):
    """The factorised physics of ``obj`` (cached; see :mod:`lipgen.blender.physics_cache`)."""
    return physics_for_object(obj, physics_spec(obj))


def physics_for_object(obj, spec: PhysicsSpec):
    """:func:`lipgen.blender.physics_for`, with a broken face shown to the artist.

    The core numbers faces as Blender's triangulation does; a :class:`lipgen.MeshError` naming
    one is re-raised naming its Blender polygon, which is also selected (Edit Mode shows it).
    """
    try:
        return physics_for(spec)
    except MeshError as exc:
        found = re.search(r"\bface (\d+)", str(exc))
        if found is None:
            raise
        _, poly = bridge.mesh_triangles(obj.data)
        p = int(poly[int(found.group(1))])
        bridge.select_polygons(obj.data, [p])
        raise MeshError(f"{exc} [that triangle is part of polygon {p}, now selected: look at it "
                        "in Edit Mode]") from exc


def markers_of(obj) -> tuple[np.ndarray, tuple[str, ...] | None]:
    """Marker nodes and names: the stored order and names if they still match the markers
    vertex group (LipGen's lips), else the group's vertices in index order (no names)."""
    s = obj.lipgen
    if not s.markers_group or obj.vertex_groups.get(s.markers_group) is None:
        return np.zeros(0, np.int64), None
    nodes = bridge.vertex_group_nodes(obj, s.markers_group)
    if s.marker_order:
        order = np.array([int(i) for i in s.marker_order.split(",")], np.int64)
        names = tuple(s.marker_names.split(",")) if s.marker_names else None
        if np.array_equal(np.sort(order), nodes) and (names is None or len(names) == len(order)):
            return order, names
    return nodes, None


def lip_mesh_of(obj) -> LipMesh:
    """``obj``'s rest shape as a :class:`lipgen.LipMesh` (mm; anchors, regions, markers)."""
    s = obj.lipgen
    tris, poly = bridge.mesh_triangles(obj.data)
    anchors = np.zeros(0, np.int64)
    if s.anchors_group and obj.vertex_groups.get(s.anchors_group) is not None:
        anchors = bridge.vertex_group_nodes(obj, s.anchors_group)
    markers, names = markers_of(obj)
    return LipMesh(bridge.rest_vertices(obj) * s.unit_mm, tris, regions_per_triangle(obj, poly),
                   anchors, markers, names, name=obj.name)


def topology_id(obj) -> str:
    tris, _ = bridge.mesh_triangles(obj.data)
    return LipMesh(bridge.rest_vertices(obj), tris, name=obj.name).topology_id


def lips_resolution_of(obj) -> int:
    """The procedural resolution of a LipGen-lips object, or :class:`UserError`."""
    from lipgen.blender.speech import lips_resolution

    r = lips_resolution(len(obj.data.vertices), topology_id(obj))
    if r is None:
        raise UserError(f"{obj.name!r} is not LipGen's procedural lips (its topology differs): "
                        "speech is performed by lipgen's synthetic subject, whose mesh is "
                        "LipGen's lips. Add LipGen Lips, or animate this mesh from curves")
    return r


# ---- modes --------------------------------------------------------------------------------
def clear_modes(obj, keep_animation: bool = False) -> None:
    """Remove the mode shape keys, their drivers, the sliders (and their keyframes)."""
    s = obj.lipgen
    for item in s.modes:
        bridge.remove_shape_key(obj, mode_key_name(item.name))
    bridge.remove_shape_key(obj, MEAN_KEY)
    if not keep_animation:
        bridge.remove_fcurves(obj, "lipgen.modes[")
    s.modes.clear()
    s.modes_source = ""
    s.modes_topology_id = ""


def apply_mode_basis(obj, basis: ModeBasis) -> None:
    """Make ``basis`` the object's modes: one driven shape key and one slider per mode.

    Keyframes on sliders that still exist are kept; the others are removed.
    """
    s = obj.lipgen
    n = len(obj.data.vertices)
    if basis.n_nodes != n:
        raise UserError(f"the modes are for a mesh of {basis.n_nodes} vertices; {obj.name!r} has {n}")
    old_count = len(s.modes)
    clear_modes(obj, keep_animation=True)
    for i in range(basis.n_modes, old_count):
        bridge.remove_fcurves(obj, f"lipgen.modes[{i}]")
    rest = bridge.rest_vertices(obj)
    unit = s.unit_mm
    if np.abs(basis.mean).max() > 0:
        kb = bridge.ensure_shape_key(obj, MEAN_KEY, rest + basis.mean / unit, (0.0, 1.0))
        bridge.add_sum_driver(kb, obj, "lipgen.mean_weight")
    offsets = basis.offsets() / unit
    for i, name in enumerate(basis.names):
        item = s.modes.add()
        item.name = name
        item.scale = float(basis.scales[i])
        kb = bridge.ensure_shape_key(obj, mode_key_name(name), rest + offsets[i],
                                     (-SLIDER_LIMIT, SLIDER_LIMIT))
        bridge.add_sum_driver(kb, obj, slider_path(i))
    s.modes_source = basis.source
    s.modes_topology_id = basis.topology_id
    obj.data.update()
    obj.update_tag()


def mode_basis(obj) -> ModeBasis:
    """The object's modes read back from its shape keys (mm, the core's units)."""
    s = obj.lipgen
    if not len(s.modes):
        raise UserError(f"{obj.name!r} has no LipGen modes; load or build modes first")
    keys = obj.data.shape_keys
    rest = bridge.rest_vertices(obj)
    unit = s.unit_mm
    comps = []
    for item in s.modes:
        kb = None if keys is None else keys.key_blocks.get(mode_key_name(item.name))
        if kb is None:
            raise UserError(f"the shape key {mode_key_name(item.name)!r} of slider {item.name!r} "
                            "is missing; rebuild the modes")
        comps.append((bridge.shape_key_co(kb) - rest) * unit / item.scale)
    mean_kb = None if keys is None else keys.key_blocks.get(MEAN_KEY)
    mean = np.zeros_like(rest) if mean_kb is None else (bridge.shape_key_co(mean_kb) - rest) * unit
    return ModeBasis(mean, np.array(comps), np.array([m.scale for m in s.modes]),
                     tuple(m.name for m in s.modes), s.modes_topology_id, s.modes_source)


def write_displacement_key(obj, name: str, displacement_mm: np.ndarray, value: float = 1.0):
    """Shape key ``name`` = rest + displacement (converted from mm to mesh units)."""
    rest = bridge.rest_vertices(obj)
    kb = bridge.ensure_shape_key(obj, name, rest + np.asarray(displacement_mm) / obj.lipgen.unit_mm,
                                 (-SLIDER_LIMIT, SLIDER_LIMIT))
    kb.value = value
    obj.data.update()
    return kb
