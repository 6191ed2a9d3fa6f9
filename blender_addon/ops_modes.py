"""Operators for modes: load a trained model, build modes from the physics, train, clear, key."""

from __future__ import annotations

from pathlib import Path

import bpy
import numpy as np
from bpy.props import EnumProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from lipgen.blender import ModeBasis

from . import bridge, lipobject
from .lipobject import UserError
from .ops_common import LipgenOperator, lipgen_object


class OBJECT_OT_lipgen_load_modes(LipgenOperator, bpy.types.Operator, ImportHelper):
    """Load a trained mode model (model.npz from `lipgen train`): one driven shape key and slider per mode"""

    bl_idname = "object.lipgen_load_modes"
    bl_label = "Load Modes"

    filename_ext = ".npz"
    filter_glob: StringProperty(default="*.npz", options={"HIDDEN"})

    def run(self, context):
        from lipgen.modes.model import ModeModel

        obj = lipgen_object(context)
        path = Path(bpy.path.abspath(self.filepath))
        model = ModeModel.load(path)
        # The core's own check: refuses (TopologyMismatchError) a model of another topology.
        model.check_mesh(lipobject.lip_mesh_of(obj))
        basis = ModeBasis.from_model(model, source=path.name)
        lipobject.apply_mode_basis(obj, basis)
        self.report({"INFO"}, f"loaded {basis.n_modes} modes from {path.name}")


class OBJECT_OT_lipgen_build_modes(LipgenOperator, bpy.types.Operator):
    """Build modes in place from the physics: the softest ways this mesh can deform"""

    bl_idname = "object.lipgen_build_modes"
    bl_label = "Build Modes from Physics"

    n_modes: IntProperty(name="Modes", default=10, min=1, max=64)

    def invoke(self, context, event):
        return context.window_manager.invoke_props_dialog(self)

    def run(self, context):
        obj = lipgen_object(context)
        basis = ModeBasis.from_physics(lipobject.physics(obj), self.n_modes)
        lipobject.apply_mode_basis(obj, basis)
        self.report({"INFO"}, f"built {basis.n_modes} modes from the physics")


def _frames_from_file(path: Path, rest_mm: np.ndarray) -> np.ndarray:
    with np.load(path, allow_pickle=False) as data:
        d = {k: data[k] for k in data.files}
    for key, is_positions in (("displacements", False), ("U", False), ("vertices", True)):
        if key in d:
            A = np.asarray(d[key], np.float64)
            if A.ndim == 2 and A.shape[1] == 3 * len(rest_mm):
                A = A.reshape(len(A), -1, 3)
            if A.ndim != 3 or A.shape[1:] != rest_mm.shape:
                raise UserError(f"{path.name}: {key!r} has shape {A.shape}; this mesh needs "
                                f"(frames, {len(rest_mm)}, 3)")
            return A - rest_mm if is_positions else A
    raise UserError(f"{path.name} has none of 'displacements', 'U' or 'vertices' (found {sorted(d)})")


class OBJECT_OT_lipgen_train_modes(LipgenOperator, bpy.types.Operator):
    """Train modes (PCA, thesis App. B) from example shapes: shape keys, the animation, or a file"""

    bl_idname = "object.lipgen_train_modes"
    bl_label = "Train Modes"

    source: EnumProperty(
        name="From", default="SHAPE_KEYS",
        items=(("SHAPE_KEYS", "Shape keys", "Every shape key that is not the Basis or LipGen's own"),
               ("ANIMATION", "Animation", "The evaluated mesh at every frame of the scene range"),
               ("FILE", "File", "An npz with 'displacements' or 'vertices' (frames, n, 3) in mm"),
               ("SPEECH", "Speech", "Random gestures of every action of lipgen's synthetic "
                "subject (LipGen's lips only): modes that can follow viseme scripts"),
               ("DATASET", "Dataset", "The true vertices of a lipgen dataset folder (lipgen "
                "generate); pick the folder or its manifest.json")))
    filepath: StringProperty(name="File", subtype="FILE_PATH", default="")
    n_modes: IntProperty(name="Modes", default=10, min=1, max=64)

    def invoke(self, context, event):
        return context.window_manager.invoke_props_dialog(self, width=360)

    def _frames(self, context, obj) -> np.ndarray:
        unit = obj.lipgen.unit_mm
        rest = bridge.rest_vertices(obj)
        if self.source == "FILE":
            return _frames_from_file(Path(bpy.path.abspath(self.filepath)), rest * unit)
        if self.source == "DATASET":
            from lipgen.blender.training import dataset_displacements

            if not self.filepath:
                raise UserError("choose the dataset folder (or its manifest.json) in File")
            return dataset_displacements(bpy.path.abspath(self.filepath), len(rest),
                                         lipobject.topology_id(obj))
        if self.source == "SPEECH":
            from lipgen.blender.speech import gesture_displacements

            return gesture_displacements(lipobject.lips_resolution_of(obj))
        if self.source == "SHAPE_KEYS":
            keys = obj.data.shape_keys
            blocks = [] if keys is None else [
                kb for kb in keys.key_blocks
                if kb != keys.reference_key and not kb.name.startswith("LipGen ")]
            return np.array([(bridge.shape_key_co(kb) - rest) * unit for kb in blocks])
        scene = context.scene
        current = scene.frame_current
        frames = []
        try:
            for f in range(scene.frame_start, scene.frame_end + 1):
                scene.frame_set(f)
                frames.append((bridge.evaluated_vertices(obj) - rest) * unit)
        finally:
            scene.frame_set(current)
        return np.array(frames)

    def run(self, context):
        obj = lipgen_object(context)
        U = self._frames(context, obj)
        if len(U) < 2:
            raise UserError(f"training needs at least 2 example shapes, found {len(U)} "
                            f"({self.source.lower().replace('_', ' ')})")
        n = min(self.n_modes, len(U) - 1)  # F shapes have at most F - 1 modes about their mean
        basis = ModeBasis.fit(U, n, mesh=lipobject.lip_mesh_of(obj),
                              source=f"trained on {len(U)} {self.source.lower().replace('_', ' ')}")
        # Sliders drive the rig from the training shapes' own mean: existing shape keys (the
        # examples) stay as they are; the mean goes into its own key at weight 1.
        lipobject.apply_mode_basis(obj, basis)
        self.report({"INFO"}, f"trained {basis.n_modes} modes on {len(U)} shapes")


class OBJECT_OT_lipgen_clear_modes(LipgenOperator, bpy.types.Operator):
    """Remove the mode sliders, their shape keys, drivers and keyframes"""

    bl_idname = "object.lipgen_clear_modes"
    bl_label = "Clear Modes"

    def run(self, context):
        obj = lipgen_object(context)
        n = len(obj.lipgen.modes)
        lipobject.clear_modes(obj)
        obj.update_tag()
        self.report({"INFO"}, f"removed {n} modes")


class OBJECT_OT_lipgen_key_modes(LipgenOperator, bpy.types.Operator):
    """Insert a keyframe on every mode slider at the current frame"""

    bl_idname = "object.lipgen_key_modes"
    bl_label = "Keyframe Sliders"

    def run(self, context):
        obj = lipgen_object(context)
        frame = context.scene.frame_current
        if not len(obj.lipgen.modes):
            raise UserError("there are no mode sliders to keyframe; load or build modes first")
        for i in range(len(obj.lipgen.modes)):
            obj.keyframe_insert(lipobject.slider_path(i), frame=frame, group="LipGen")
        self.report({"INFO"}, f"keyed {len(obj.lipgen.modes)} sliders at frame {frame}")


classes = (OBJECT_OT_lipgen_load_modes, OBJECT_OT_lipgen_build_modes, OBJECT_OT_lipgen_train_modes,
           OBJECT_OT_lipgen_clear_modes, OBJECT_OT_lipgen_key_modes)
