"""Reconstruction from raw camera-mirror frames (thesis ch. 3, §4.1).

calibrate -> detect dots -> track -> triangulate -> normalise -> reach per frame:

* :mod:`~lipgen.recon.calibrate`: the rig from chessboard images (OpenCV).
* :mod:`~lipgen.recon.dots`: ink-dot detection and sub-pixel centroids.
* :mod:`~lipgen.recon.pointreg`, :mod:`~lipgen.recon.association`: matching dots to markers.
* :mod:`~lipgen.recon.track`: normalised-correlation tracking.
* :mod:`~lipgen.recon.steps`: tracking both views, triangulation, reach fields.
* :mod:`~lipgen.recon.similarity`, :mod:`~lipgen.recon.headpose`, :mod:`~lipgen.recon.normalize`:
  into the model frame.
* :mod:`~lipgen.recon.pipeline`: ``lipgen reconstruct``, a dataset folder to :class:`Reconstruction`.
"""

from lipgen.recon.pipeline import Reconstruction, reconstruct_dataset

__all__ = ["Reconstruction", "reconstruct_dataset"]
