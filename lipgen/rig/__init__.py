"""The camera-mirror rig and the renderer-independent scene (OpenCV camera convention).

* :mod:`~lipgen.rig.pinhole`: :class:`PinholeCamera` (projection, distortion, triangulation).
* :mod:`~lipgen.rig.camera`: :class:`MirrorRig` (real + virtual camera), :func:`default_rig`, split views.
* :mod:`~lipgen.rig.scene`: materials, meshes and lights, with no renderer in them.
* :mod:`~lipgen.rig.target`: the chessboard calibration target and its poses.
* :mod:`~lipgen.rig.visibility`: which points the surface hides from a camera.
* :mod:`~lipgen.rig.render`: the pyrender (EGL) renderer of a scene through the rig.
"""

from lipgen.rig.camera import VIEWS, MirrorRig, default_rig
from lipgen.rig.pinhole import PinholeCamera

__all__ = ["PinholeCamera", "MirrorRig", "VIEWS", "default_rig"]
