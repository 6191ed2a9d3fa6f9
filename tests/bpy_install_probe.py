"""Run by test_blender_extension.py in a bare interpreter (``python -I -S``) whose only
packages are bpy and numpy: install the built extension zip into a fresh Blender user folder,
enable it, and use it. Everything else (lipgen, scipy) must come from the zip's wheels.

``python -I -S bpy_install_probe.py SITE_DIR ZIP OUT.json``
"""

import json
import sys

sys.path.insert(0, sys.argv[1])

import bpy  # noqa: E402
import numpy as np  # noqa: E402


def main(zip_path: str, out: str) -> None:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    result = bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default",
                                                      enable_on_install=True)
    import scipy

    import lipgen
    from lipgen.fem import Physics

    assert bpy.ops.object.lipgen_add_lips(resolution=0) == {"FINISHED"}
    obj = bpy.context.active_object
    nodes = [int(i) for i in lipgen.lip_mesh(0).markers[:3]]
    vg = obj.vertex_groups.new(name="LipGen Force")
    vg.add(nodes, 1.0, "REPLACE")
    assert bpy.ops.object.lipgen_apply_force(group="LipGen Force", units="FORCE", direction=(0, -1, 0),
                                             magnitude=1.0) == {"FINISHED"}
    dg = bpy.context.evaluated_depsgraph_get()
    me = obj.evaluated_get(dg).to_mesh()
    co = np.empty(3 * len(me.vertices), np.float32)
    me.vertices.foreach_get("co", co)
    lm = lipgen.lip_mesh(0)
    F = np.zeros((lm.n_nodes, 3))
    F[nodes] = [0.0, 0.0, 1.0]
    dev = float(np.abs(co.reshape(-1, 3) - lm.vertices - Physics(lm).displace(F)).max())
    # lipgen's USD export through Blender's own bundled pxr (nothing else provides one here).
    usd_path = out[: -len(".json")] + ".usda"
    bpy.context.scene.frame_end = 3
    assert bpy.ops.object.lipgen_export_usd(filepath=usd_path, content="POINTS") == {"FINISHED"}
    import pxr

    with open(out, "w") as fh:
        json.dump({"install": sorted(result), "lipgen": lipgen.__file__, "scipy": scipy.__file__,
                   "addon_modules": sorted(m for m in sys.modules if m.startswith("bl_ext.")
                                           and m.endswith(".lipgen")),
                   "force_max_dev_mm": dev, "pxr": pxr.__file__, "usd": usd_path}, fh)


if __name__ == "__main__":
    main(sys.argv[2], sys.argv[3])
