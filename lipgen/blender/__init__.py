"""The data side of the Blender add-on: everything it computes, with numpy and lipgen only.

The add-on (``blender_addon/``) is a thin bpy layer over this package, in the way Blender's
glTF add-on separates its ``io`` half from its ``blender`` half. Nothing here imports bpy, so
it is tested, benchmarked and reused (USD export, scripts) without Blender.

- :mod:`~lipgen.blender.modebasis`: :class:`ModeBasis`, the modes a rig drives (from a trained
  :class:`~lipgen.modes.ModeModel`, from the physics, or fitted to frames), with the per-mode
  slider scale that keeps shape-key values inside Blender's [-10, 10] slider range.
- :mod:`~lipgen.blender.physics_cache`: the factorised :class:`~lipgen.fem.Physics` per mesh and
  stiffness setting, cached in memory by content.
- :mod:`~lipgen.blender.forces`: force fields on chosen vertices, the unit responses behind the
  live force preview, and reach goals from moved vertices.
- :mod:`~lipgen.blender.curves`: coefficient curves from npz/CSV files, resampled to frames.
- :mod:`~lipgen.blender.speech`: viseme scripts performed by lipgen's synthetic subject, on the
  procedural lips.
- :mod:`~lipgen.blender.lipsync`: speech recordings performed by the subject, followed by the
  procedural lips node for node and by an artist's mesh through its markers.
- :mod:`~lipgen.blender.packaging`: the installable extension zips.
"""

from __future__ import annotations

from lipgen.blender.curves import CoefficientCurves, load_curves
from lipgen.blender.forces import ForceResponses, ReachGoals, force_field, moved_nodes, reach_goals
from lipgen.blender.modebasis import ModeBasis
from lipgen.blender.physics_cache import PhysicsSpec, clear_physics_cache, physics_for

__all__ = [
    "ModeBasis",
    "PhysicsSpec",
    "physics_for",
    "clear_physics_cache",
    "ForceResponses",
    "force_field",
    "moved_nodes",
    "reach_goals",
    "ReachGoals",
    "CoefficientCurves",
    "load_curves",
]
