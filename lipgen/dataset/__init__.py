"""Datasets on disk: the documented layout and its reader, and the generator that writes them.

* :mod:`~lipgen.dataset.layout`: :class:`Dataset`, the reader.
* :mod:`~lipgen.dataset.settings`: :class:`GenerateSettings`, everything that fixes a dataset's bytes.
* :mod:`~lipgen.dataset.manifest`: the manifest, its checks and the files' paths.
* :mod:`~lipgen.dataset.presets`: ``--preset easy|default|hard``.
* :mod:`~lipgen.dataset.simulation`: the subject's motion and each frame's truth, before rendering.
* :mod:`~lipgen.dataset.generate`: ``lipgen generate``: simulate, render and write a dataset
  (:mod:`~lipgen.dataset.worker`: rendering and writing one frame; :mod:`~lipgen.dataset.folder`:
  the folder it writes into; :mod:`~lipgen.dataset.film`: image conditions per frame).
* :mod:`~lipgen.dataset.footage`: a user's own recording in the same layout.
"""

from lipgen.dataset.layout import (
    TRUTH_FIELDS,
    CalibrationFrame,
    Dataset,
    DatasetFrame,
    GenerateSettings,
    build_manifest,
    calib_paths,
    extra_paths,
    frame_paths,
    mask_labels,
    validate_manifest,
)

__all__ = ["Dataset", "DatasetFrame", "CalibrationFrame", "GenerateSettings", "TRUTH_FIELDS",
           "build_manifest", "validate_manifest", "frame_paths", "calib_paths", "extra_paths", "mask_labels"]
