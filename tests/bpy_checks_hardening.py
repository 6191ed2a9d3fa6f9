"""Inside Blender (pip bpy): an artist's mesh checked at set-up (cracks, fins, units, weak
anchors) and slider values beyond [0, 1] through USD and back (issue 20)."""

from __future__ import annotations

import bpy
import numpy as np
from bpy_checks_addon import _sheet, add_lips, call_error, evaluated, fitted_model, fresh, set_group


def _anchor_bottom(obj, count: int | None = None) -> None:
    V = np.array([v.co for v in obj.data.vertices])
    edge = np.flatnonzero(V[:, 1] < V[:, 1].min() + 1e-6)
    set_group(obj, "LipGen Anchors", edge if count is None else edge[:count])


def _cracked_sheet(name: str, nx: int = 12, ny: int = 8):
    """A sheet (metres) whose middle column of vertices is split: the right half has copies."""
    obj = _sheet(name, nx, ny)
    me = obj.data
    V = np.array([v.co for v in me.vertices])
    faces = [list(p.vertices) for p in me.polygons]
    col = nx // 2
    mid = [j * nx + col for j in range(ny)]
    copy = {v: len(V) + k for k, v in enumerate(mid)}
    right = [f for f in faces if V[f, 0].mean() > V[mid[0], 0]]
    for f in right:
        f[:] = [copy.get(v, v) for v in f]
    verts = np.vstack([V, V[mid]]).tolist()
    new = bpy.data.meshes.new(name)
    new.from_pydata(verts, [], faces)
    obj.data = new
    return obj, mid, sorted(copy.values())


def check_artist_mesh() -> dict:
    fresh()
    out = {}
    obj, mid, copies = _cracked_sheet("Cracked")
    _anchor_bottom(obj)
    out["cracked"] = call_error(bpy.ops.object.lipgen_setup_mesh)
    sel = np.array([v.select for v in obj.data.vertices])
    out["selected"] = np.flatnonzero(sel).tolist()
    out["expected"] = sorted(mid + copies)
    out["enabled_after_refusal"] = obj.lipgen.enabled
    n_before = len(obj.data.vertices)
    assert bpy.ops.object.lipgen_weld_cracks(distance_mm=1e-3) == {"FINISHED"}
    out["welded"] = n_before - len(obj.data.vertices)
    _anchor_bottom(obj)
    out["setup_after_weld"] = sorted(bpy.ops.object.lipgen_setup_mesh())
    out["warnings_ok_mesh"] = obj.lipgen.warnings

    fin = _sheet("Fin")
    me = fin.data
    a, b = me.polygons[38].vertices[0], me.polygons[38].vertices[1]  # an interior edge (row 3)
    V = np.array([v.co for v in me.vertices])
    faces = [list(p.vertices) for p in me.polygons] + [[a, b, len(V)]]
    new = bpy.data.meshes.new("Fin")
    new.from_pydata(np.vstack([V, (V[a] + V[b]) / 2 + [0, 0, 0.005]]).tolist(), [], faces)
    fin.data = new
    bpy.context.view_layer.objects.active = fin
    _anchor_bottom(fin)
    out["fin"] = call_error(bpy.ops.object.lipgen_setup_mesh)

    big = _sheet("Millimetres")  # a millimetre mesh at object scale 1: read as metres, 40 m wide
    for v in big.data.vertices:
        v.co *= 1000.0
    bpy.context.view_layer.objects.active = big
    _anchor_bottom(big)
    assert bpy.ops.object.lipgen_setup_mesh() == {"FINISHED"}
    out["units"] = big.lipgen.warnings

    weak = _sheet("Weak")
    bpy.context.view_layer.objects.active = weak
    _anchor_bottom(weak, count=2)
    result = bpy.ops.object.lipgen_setup_mesh()
    out["weak"] = weak.lipgen.warnings if result == {"FINISHED"} else f"refused: {result}"
    return out


def check_usd_slider_round_trip(tmp: str) -> dict:
    """Slider values 2 and -1.5 exported by the add-on (unit weights) and re-imported by Blender."""
    fresh()
    fitted_model(f"{tmp}/model.npz")
    obj = add_lips(0)
    bpy.ops.object.lipgen_load_modes(filepath=f"{tmp}/model.npz")
    scene = bpy.context.scene
    scene.frame_start = scene.frame_end = 1
    values = [2.0, -1.5, 0.5, 0.0, 1.0, -0.25]
    for m, v in zip(obj.lipgen.modes, values, strict=False):
        m.value = v
    scene.frame_set(1)
    want = evaluated(obj)
    out = {}
    for rng in ("UNIT", "SIGNED"):
        path = f"{tmp}/lips_{rng.lower()}.usda"
        bpy.context.view_layer.objects.active = obj
        assert bpy.ops.object.lipgen_export_usd(filepath=path, content="BLEND_SHAPES",
                                                weight_range=rng) == {"FINISHED"}
        keep = bpy.context.scene
        bpy.ops.wm.usd_import(filepath=path)
        back = [o for o in bpy.data.objects if o.type == "MESH" and o is not obj][-1]
        keep.frame_set(1)
        got = evaluated(back)
        out[rng] = float(np.abs(got - want).max())
        bpy.data.objects.remove(back)
    out["peak_mm"] = float(np.abs(want - np.array([v.co for v in obj.data.vertices])).max())
    return out
