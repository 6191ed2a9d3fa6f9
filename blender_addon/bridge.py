"""The only place that converts between Blender data and numpy arrays.

Everything goes through ``foreach_get`` / ``foreach_set`` (one C loop per array, no Python loop
per vertex), except vertex-group membership, which Blender exposes per vertex only.
Arrays leave this module as float64 / int64; Blender stores coordinates as float32.
"""

from __future__ import annotations

import bpy
import numpy as np

__all__ = [
    "mesh_vertices", "set_mesh_vertices", "mesh_triangles", "new_mesh", "polygon_loops",
    "select_polygons", "select_vertices", "selected_vertices", "face_attribute", "set_face_attribute",
    "point_vectors",
    "set_point_vectors", "vertex_group_nodes", "set_vertex_group", "shape_key_co", "set_shape_key_co",
    "ensure_basis", "ensure_shape_key", "remove_shape_key", "add_sum_driver", "remove_driver",
    "fcurve_ensure", "set_keyframes", "remove_fcurves", "evaluated_vertices", "rest_vertices",
    "edit_vertices", "set_edit_vertices",
]


# ---- geometry -----------------------------------------------------------------------------
def mesh_vertices(mesh: bpy.types.Mesh) -> np.ndarray:
    """(n, 3) float64 vertex positions of a mesh datablock (its own coordinates)."""
    co = np.empty(3 * len(mesh.vertices), np.float32)
    mesh.vertices.foreach_get("co", co)
    return co.reshape(-1, 3).astype(np.float64)


def set_mesh_vertices(mesh: bpy.types.Mesh, vertices: np.ndarray) -> None:
    mesh.vertices.foreach_set("co", np.asarray(vertices, np.float32).ravel())
    mesh.update()


def mesh_triangles(mesh: bpy.types.Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Blender's own triangulation: ``(m, 3)`` vertex indices and ``(m,)`` source polygon."""
    mesh.calc_loop_triangles()
    m = len(mesh.loop_triangles)
    tris = np.empty(3 * m, np.int32)
    mesh.loop_triangles.foreach_get("vertices", tris)
    poly = np.empty(m, np.int32)
    mesh.loop_triangles.foreach_get("polygon_index", poly)
    return tris.reshape(-1, 3).astype(np.int64), poly.astype(np.int64)


def new_mesh(name: str, vertices: np.ndarray, faces: np.ndarray) -> bpy.types.Mesh:
    """A new mesh datablock with triangles ``faces`` (m, 3) over ``vertices`` (n, 3)."""
    V = np.asarray(vertices, np.float32)
    F = np.asarray(faces, np.int32)
    me = bpy.data.meshes.new(name)
    me.vertices.add(len(V))
    me.vertices.foreach_set("co", V.ravel())
    me.loops.add(F.size)
    me.loops.foreach_set("vertex_index", F.ravel())
    me.polygons.add(len(F))
    me.polygons.foreach_set("loop_start", np.arange(0, F.size, 3, dtype=np.int32))
    me.update(calc_edges=True)
    me.validate(verbose=False)
    return me


def polygon_loops(mesh: bpy.types.Mesh) -> tuple[np.ndarray, np.ndarray]:
    """The polygons' corners: ``(L,)`` vertex of each loop and ``(p,)`` first loop of each polygon."""
    loop_vert = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", loop_vert)
    loop_start = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_start", loop_start)
    return loop_vert.astype(np.int64), loop_start.astype(np.int64)


def selected_vertices(mesh: bpy.types.Mesh) -> np.ndarray:
    """Indices of the selected vertices (object-mode data; leave edit mode first)."""
    sel = np.empty(len(mesh.vertices), bool)
    mesh.vertices.foreach_get("select", sel)
    return np.flatnonzero(sel).astype(np.int64)


def select_polygons(mesh: bpy.types.Mesh, polygons) -> None:
    """Select exactly ``polygons`` (and their vertices); object-mode data."""
    sel = np.zeros(len(mesh.polygons), bool)
    sel[np.asarray(polygons, np.int64)] = True
    mesh.polygons.foreach_set("select", sel)
    vsel = np.zeros(len(mesh.vertices), bool)
    loop_vert, loop_start = polygon_loops(mesh)
    counts = np.diff(np.append(loop_start, len(loop_vert)))
    vsel[loop_vert[np.repeat(sel, counts)]] = True
    mesh.vertices.foreach_set("select", vsel)
    mesh.update()


def select_vertices(mesh: bpy.types.Mesh, vertices) -> None:
    """Select exactly ``vertices`` (no faces); object-mode data."""
    mesh.polygons.foreach_set("select", np.zeros(len(mesh.polygons), bool))
    vsel = np.zeros(len(mesh.vertices), bool)
    vsel[np.asarray(vertices, np.int64)] = True
    mesh.vertices.foreach_set("select", vsel)
    mesh.update()


def face_attribute(mesh: bpy.types.Mesh, name: str) -> np.ndarray | None:
    """(p,) int64 values of an integer face (polygon) attribute, or None if it is absent."""
    attr = mesh.attributes.get(name)
    if attr is None or attr.domain != "FACE" or attr.data_type != "INT":
        return None
    out = np.empty(len(mesh.polygons), np.int32)
    attr.data.foreach_get("value", out)
    return out.astype(np.int64)


def set_face_attribute(mesh: bpy.types.Mesh, name: str, values: np.ndarray) -> None:
    attr = mesh.attributes.get(name)
    if attr is not None and (attr.domain != "FACE" or attr.data_type != "INT"):
        mesh.attributes.remove(attr)
        attr = None
    if attr is None:
        attr = mesh.attributes.new(name, "INT", "FACE")
    attr.data.foreach_set("value", np.asarray(values, np.int32))


def point_vectors(mesh: bpy.types.Mesh, name: str) -> np.ndarray | None:
    """(n, 3) float64 values of a float-vector point attribute, or None if it is absent."""
    attr = mesh.attributes.get(name)
    if attr is None or attr.domain != "POINT" or attr.data_type != "FLOAT_VECTOR":
        return None
    out = np.empty(3 * len(mesh.vertices), np.float32)
    attr.data.foreach_get("vector", out)
    return out.reshape(-1, 3).astype(np.float64)


def set_point_vectors(mesh: bpy.types.Mesh, name: str, values: np.ndarray | None) -> None:
    """Write (or with None, remove) a float-vector point attribute."""
    attr = mesh.attributes.get(name)
    if attr is not None and (values is None or attr.domain != "POINT"
                             or attr.data_type != "FLOAT_VECTOR"):
        mesh.attributes.remove(attr)
        attr = None
    if values is None:
        return
    if attr is None:
        attr = mesh.attributes.new(name, "FLOAT_VECTOR", "POINT")
    attr.data.foreach_set("vector", np.asarray(values, np.float32).ravel())


def vertex_group_nodes(obj: bpy.types.Object, name: str) -> np.ndarray:
    """Sorted indices of the vertices in vertex group ``name`` with a weight above zero."""
    vg = obj.vertex_groups.get(name)
    if vg is None:
        raise KeyError(name)
    gi = vg.index
    out = [v.index for v in obj.data.vertices for g in v.groups if g.group == gi and g.weight > 0.0]
    return np.array(sorted(out), dtype=np.int64)


def set_vertex_group(obj: bpy.types.Object, name: str, nodes) -> bpy.types.VertexGroup:
    """Make vertex group ``name`` hold exactly ``nodes`` (weight 1)."""
    vg = obj.vertex_groups.get(name)
    if vg is None:
        vg = obj.vertex_groups.new(name=name)
    else:
        vg.remove(range(len(obj.data.vertices)))
    idx = [int(i) for i in np.asarray(nodes).ravel()]
    if idx:
        vg.add(idx, 1.0, "REPLACE")
    return vg


# ---- edit mode ----------------------------------------------------------------------------
def edit_vertices(bm) -> np.ndarray:
    """(n, 3) float64 positions of a BMesh's vertices (in Edit Mode: the edited shape key)."""
    return np.array([v.co[:] for v in bm.verts], dtype=np.float64).reshape(-1, 3)


def set_edit_vertices(bm, co: np.ndarray, nodes: np.ndarray) -> None:
    """Move vertices ``nodes`` of a BMesh to ``co[nodes]``."""
    bm.verts.ensure_lookup_table()
    verts = bm.verts
    for i in np.asarray(nodes, np.int64).tolist():
        verts[i].co = co[i]


# ---- shape keys ---------------------------------------------------------------------------
def shape_key_co(key_block: bpy.types.ShapeKey) -> np.ndarray:
    co = np.empty(3 * len(key_block.data), np.float32)
    key_block.data.foreach_get("co", co)
    return co.reshape(-1, 3).astype(np.float64)


def set_shape_key_co(key_block: bpy.types.ShapeKey, co: np.ndarray) -> None:
    key_block.data.foreach_set("co", np.asarray(co, np.float32).ravel())


def rest_vertices(obj: bpy.types.Object) -> np.ndarray:
    """(n, 3) rest positions: the reference (Basis) shape key if there is one, else the mesh."""
    keys = obj.data.shape_keys
    if keys is not None and keys.reference_key is not None:
        return shape_key_co(keys.reference_key)
    return mesh_vertices(obj.data)


def ensure_basis(obj: bpy.types.Object) -> bpy.types.ShapeKey:
    keys = obj.data.shape_keys
    if keys is None or keys.reference_key is None:
        return obj.shape_key_add(name="Basis", from_mix=False)
    return keys.reference_key


def ensure_shape_key(obj: bpy.types.Object, name: str, co: np.ndarray | None = None,
                     slider_range: tuple[float, float] = (0.0, 1.0)) -> bpy.types.ShapeKey:
    """Shape key ``name`` (created from the Basis if missing), optionally set to ``co``."""
    ensure_basis(obj)
    kb = obj.data.shape_keys.key_blocks.get(name)
    if kb is None:
        kb = obj.shape_key_add(name=name, from_mix=False)
    kb.slider_min, kb.slider_max = slider_range
    if co is not None:
        set_shape_key_co(kb, co)
    return kb


def remove_shape_key(obj: bpy.types.Object, name: str) -> bool:
    keys = obj.data.shape_keys
    kb = None if keys is None else keys.key_blocks.get(name)
    if kb is None:
        return False
    remove_driver(kb)
    obj.shape_key_remove(kb)
    return True


def add_sum_driver(key_block: bpy.types.ShapeKey, target: bpy.types.ID, data_path: str) -> bpy.types.FCurve:
    """Drive ``key_block.value`` by a SUM driver of one single-property variable (no Python)."""
    remove_driver(key_block)
    fc = key_block.driver_add("value")
    drv = fc.driver
    drv.type = "SUM"
    var = drv.variables.new()
    var.name = "slider"
    var.type = "SINGLE_PROP"
    var.targets[0].id_type = "OBJECT"
    var.targets[0].id = target
    var.targets[0].data_path = data_path
    return fc


def remove_driver(key_block: bpy.types.ShapeKey) -> None:
    key = key_block.id_data
    ad = key.animation_data
    if ad is None:
        return
    path = key_block.path_from_id("value")
    for fc in list(ad.drivers):
        if fc.data_path == path:
            ad.drivers.remove(fc)


# ---- animation ----------------------------------------------------------------------------
def fcurve_ensure(id_data: bpy.types.ID, data_path: str, index: int = 0,
                  group: str = "LipGen") -> bpy.types.FCurve:
    """The F-curve animating ``data_path`` of ``id_data``, created with its action if needed.

    Works with the layered actions of Blender 4.4+ and the flat ones of 4.2/4.3.
    """
    ad = id_data.animation_data or id_data.animation_data_create()
    if ad.action is None:
        ad.action = bpy.data.actions.new(f"{id_data.name}Action")
    act = ad.action
    if hasattr(act, "fcurve_ensure_for_datablock"):
        return act.fcurve_ensure_for_datablock(id_data, data_path, index=index, group_name=group)
    fc = act.fcurves.find(data_path, index=index)
    return fc if fc is not None else act.fcurves.new(data_path, index=index, action_group=group)


def _fcurves(id_data: bpy.types.ID):
    ad = id_data.animation_data
    if ad is None or ad.action is None:
        return None
    act = ad.action
    if hasattr(act, "fcurve_ensure_for_datablock"):
        from bpy_extras import anim_utils

        return anim_utils.animdata_get_channelbag_for_assigned_slot(ad)
    return act


_LINEAR = None


def set_keyframes(fc: bpy.types.FCurve, frames, values, replace: bool = True) -> None:
    """Write keyframes ``(frames[i], values[i])`` in one go, with linear interpolation.

    With ``replace`` the keys of ``fc`` inside [min(frames), max(frames)] are dropped first,
    so importing over an existing range does not interleave old and new keys.
    """
    global _LINEAR
    if _LINEAR is None:
        _LINEAR = bpy.types.Keyframe.bl_rna.properties["interpolation"].enum_items["LINEAR"].value
    f = np.asarray(frames, np.float64)
    v = np.asarray(values, np.float64)
    if replace and len(fc.keyframe_points):
        lo, hi = f.min(), f.max()
        old = np.empty(2 * len(fc.keyframe_points), np.float32)
        fc.keyframe_points.foreach_get("co", old)
        drop = np.flatnonzero((old[0::2] >= lo - 1e-4) & (old[0::2] <= hi + 1e-4))
        for i in drop[::-1]:
            fc.keyframe_points.remove(fc.keyframe_points[int(i)], fast=True)
    start = len(fc.keyframe_points)
    fc.keyframe_points.add(len(f))
    co = np.empty(2 * len(fc.keyframe_points), np.float32)
    fc.keyframe_points.foreach_get("co", co)
    co[2 * start:] = np.column_stack([f, v]).ravel()
    fc.keyframe_points.foreach_set("co", co)
    interp = np.empty(len(fc.keyframe_points), np.int32)
    fc.keyframe_points.foreach_get("interpolation", interp)
    interp[start:] = _LINEAR
    fc.keyframe_points.foreach_set("interpolation", interp)
    fc.update()


def remove_fcurves(id_data: bpy.types.ID, prefix: str) -> int:
    """Remove the F-curves of ``id_data`` whose data path starts with ``prefix``."""
    bag = _fcurves(id_data)
    if bag is None:
        return 0
    doomed = [fc for fc in bag.fcurves if fc.data_path.startswith(prefix)]
    for fc in doomed:
        bag.fcurves.remove(fc)
    return len(doomed)


# ---- evaluation ---------------------------------------------------------------------------
def evaluated_vertices(obj: bpy.types.Object, depsgraph: bpy.types.Depsgraph | None = None) -> np.ndarray:
    """(n, 3) vertex positions after shape keys, drivers and modifiers (object coordinates)."""
    dg = depsgraph or bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(dg)
    me = ev.to_mesh()
    try:
        return mesh_vertices(me)
    finally:
        ev.to_mesh_clear()
