"""Datasets on disk: the documented layout and its reader, and the generator that writes them.

* :mod:`~lipgen.dataset.layout`: :class:`Dataset` (the reader), the manifest and its checks, file paths.
* :mod:`~lipgen.dataset.generate`: ``lipgen generate``: simulate, render and write a dataset.
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
