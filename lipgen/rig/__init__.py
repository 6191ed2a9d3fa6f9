"""The camera-mirror rig and the renderer-independent scene (OpenCV camera convention).

* :mod:`~lipgen.rig.pinhole`: :class:`PinholeCamera` (projection, distortion, triangulation).
* :mod:`~lipgen.rig.camera`: :class:`MirrorRig` (real + virtual camera), :func:`default_rig`, split views.
* :mod:`~lipgen.rig.scene`: materials, meshes and lights, with no renderer in them.
* :mod:`~lipgen.rig.target`: the chessboard calibration target and its poses.
* :mod:`~lipgen.rig.visibility`: which points the surface hides from a camera.
* :mod:`~lipgen.rig.render`: the pyrender (EGL) renderer of a scene through the rig.
* :mod:`~lipgen.rig.cycles`: the Blender Cycles (photoreal, CPU) renderer of the same scene and rig.
* :mod:`~lipgen.rig.backends`: choosing between them by name (``generate --renderer``).
"""

from lipgen.rig.camera import VIEWS, MirrorRig, default_rig
from lipgen.rig.pinhole import PinholeCamera

__all__ = ["PinholeCamera", "MirrorRig", "VIEWS", "default_rig"]
