"""USD export through :func:`lipgen.usd.export_usd`: the modes as UsdSkel blend shapes with the
slider animation, and/or every frame baked as points.

Blender's own exporter (File > Export > Universal Scene Description) also writes LipGen's
shape keys and their driven values; this operator writes lipgen's layout instead (model frame,
millimetres, regions and markers, validated). It is meant for LipGen's lips, whose mesh data is
in the model frame; other meshes are written in their own coordinates, converted to mm.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import bpy
import numpy as np
from bpy.props import EnumProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from . import bridge, lipobject
from .lipobject import UserError
from .ops_common import LipgenOperator, lipgen_object


def ensure_pxr() -> None:
    """Make Blender's own USD Python module importable.

    Blender puts its bundled ``pxr`` on ``sys.path``; the pip ``bpy`` module carries it in the
    same place but does not, so that folder is appended when ``pxr`` is missing.
    """
    try:
        import pxr  # noqa: F401
        return
    except ImportError:
        pass
    site = os.path.join(bpy.utils.resource_path("LOCAL"), "python", "lib",
                        "python{}.{}".format(*sys.version_info[:2]), "site-packages")
    if os.path.isdir(os.path.join(site, "pxr")) and site not in sys.path:
        sys.path.append(site)


def sample_frames(context, obj, frames, points: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """Slider values ``(F, k)`` and, if asked, evaluated vertices ``(F, n, 3)`` in mm."""
    scene = context.scene
    current = scene.frame_current
    k = len(obj.lipgen.modes)
    sliders = np.zeros((len(frames), k))
    verts = [] if points else None
    try:
        for i, f in enumerate(frames):
            scene.frame_set(int(f))
            sliders[i] = [m.value for m in obj.lipgen.modes]
            if points:
                verts.append(bridge.evaluated_vertices(obj) * obj.lipgen.unit_mm)
    finally:
        scene.frame_set(current)
    return sliders, (np.array(verts) if points else None)


class OBJECT_OT_lipgen_export_usd(LipgenOperator, bpy.types.Operator, ExportHelper):
    """Export to USD with lipgen: modes as UsdSkel blend shapes animated by the sliders, or baked points"""

    bl_idname = "object.lipgen_export_usd"
    bl_label = "Export LipGen USD"

    filename_ext = ".usda"
    filter_glob: StringProperty(default="*.usda;*.usdc;*.usd;*.usdz", options={"HIDDEN"})
    content: EnumProperty(
        name="Content", default="BOTH",
        items=(("BLEND_SHAPES", "Blend shapes", "Modes as UsdSkel blend shapes; slider animation"),
               ("POINTS", "Baked points", "Every frame's evaluated vertices (forces, reach, all keys)"),
               ("BOTH", "Both", "One file, a variant set 'encoding' to switch")))

    def check(self, context):
        # Keep the extension the user typed (.usda/.usdc/.usd/.usdz) instead of forcing .usda.
        return False

    def run(self, context):
        from lipgen.usd.export import BAKED_POINTS, BLEND_SHAPES, export_usd

        obj = lipgen_object(context)
        ensure_pxr()
        scene = context.scene
        frames = np.arange(scene.frame_start, scene.frame_end + 1)
        want_shapes = self.content in ("BLEND_SHAPES", "BOTH")
        if want_shapes and not len(obj.lipgen.modes):
            if self.content == "BLEND_SHAPES":
                raise UserError("there are no modes to export as blend shapes; load or build "
                                "modes, or export baked points")
            want_shapes = False
        mesh = lipobject.lip_mesh_of(obj)
        sliders, points = sample_frames(context, obj, frames, self.content in ("POINTS", "BOTH"))
        model = weights = None
        if want_shapes:
            basis = lipobject.mode_basis(obj)
            model = basis.as_model()
            weights = basis.coefficients(sliders)
        fps = scene.render.fps / scene.render.fps_base
        path = Path(bpy.path.abspath(self.filepath))
        export_usd(path, mesh, model=model, weights=weights, points=points, fps=fps,
                   start=int(frames[0]),
                   default_encoding=BLEND_SHAPES if want_shapes else BAKED_POINTS)
        self.report({"INFO"}, f"wrote {path.name}: {len(frames)} frames"
                              + (f", {len(obj.lipgen.modes)} blend shapes" if want_shapes else "")
                              + (", baked points" if points is not None else ""))


classes = (OBJECT_OT_lipgen_export_usd,)
