"""Run by the USD tests in the shared Blender session's process (``blender_session.py``), or as a
script: import a USD file into Blender (the pip ``bpy`` module) and save what Blender made of it.

``python blender_usd_probe.py IN.usd OUT.npz [--widen]`` writes, for the first mesh object:
the evaluated vertex positions (object space, from the depsgraph) at every frame of the scene
range, the frames, the shape-key names and slider ranges, the object's world matrix, and the
scene frame range. ``--widen`` sets every shape key's slider range to Blender's widest,
[-10, 10], after the import (Blender clamps shape-key values to the slider range, [0, 1] by
default). Kept out of the test process because bpy bundles its own USD libraries.
"""

import sys

import bpy
import numpy as np


def main(src: str, out: str, widen: bool) -> None:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    result = bpy.ops.wm.usd_import(filepath=src)
    if "FINISHED" not in result:
        raise SystemExit(f"usd_import returned {result}")
    meshes = [o for o in bpy.data.objects if o.type == "MESH"]
    if not meshes:
        raise SystemExit("the import made no mesh object")
    ob = meshes[0]
    keys = ob.data.shape_keys.key_blocks if ob.data.shape_keys else []
    if widen:
        for kb in keys:
            kb.slider_min, kb.slider_max = -10.0, 10.0
    scene = bpy.context.scene
    frames = np.arange(scene.frame_start, scene.frame_end + 1)
    coords = []
    for f in frames:
        scene.frame_set(int(f))
        dg = bpy.context.evaluated_depsgraph_get()
        ev = ob.evaluated_get(dg)
        me = ev.to_mesh()
        co = np.empty(3 * len(me.vertices), np.float32)
        me.vertices.foreach_get("co", co)
        coords.append(co.reshape(-1, 3))
        ev.to_mesh_clear()
    np.savez(out, frames=frames, coords=np.stack(coords), object=ob.name,
             key_names=np.array([kb.name for kb in keys], dtype=str),
             slider=np.array([(kb.slider_min, kb.slider_max) for kb in keys], np.float64).reshape(-1, 2),
             world=np.array(ob.matrix_world, np.float64),
             objects=np.array(sorted(f"{o.name}:{o.type}" for o in bpy.data.objects), dtype=str))


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    main(args[0], args[1], "--widen" in sys.argv)
