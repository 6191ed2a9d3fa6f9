"""Non-rigid structure from motion under orthography.

- :func:`reconstruct` (``method="bregler"``, ``"dai"``, ``"dai-ba"``, ``"em-ppca"`` or ``"em-pnd"``, see
  :data:`METHODS`):
  rotations, weights and basis shapes from 2D tracks W (2F x P), optionally with missing points.
- :func:`e3d`: the benchmark's normalised 3D error; :func:`flat_e3d` the zero-depth baseline's.
- :func:`reprojection_curve` / :func:`choose_k`: K from the reprojection error (Bregler Fig 2).
- :func:`load_tracks` / :func:`save_shapes`: the ``lipgen nrsfm`` file formats.
- :func:`evaluate_on_dataset`: one view of a ``lipgen generate`` dataset, scored against its truth.
"""

from __future__ import annotations

from lipgen.nrsfm.core import (
    DEFAULT_METHOD,
    MEAN_PLUS_MODES,
    METHODS,
    Reconstruction,
    n_basis_shapes,
    reconstruct,
)
from lipgen.nrsfm.dataset_eval import dataset_tracks, evaluate_on_dataset
from lipgen.nrsfm.io import load_shapes, load_tracks, save_shapes
from lipgen.nrsfm.metrics import KCurve, choose_k, e3d, flat_e3d, plot_curve, reprojection_curve

__all__ = [
    "DEFAULT_METHOD",
    "METHODS",
    "MEAN_PLUS_MODES",
    "n_basis_shapes",
    "Reconstruction",
    "reconstruct",
    "e3d",
    "flat_e3d",
    "KCurve",
    "choose_k",
    "reprojection_curve",
    "plot_curve",
    "load_tracks",
    "save_shapes",
    "load_shapes",
    "dataset_tracks",
    "evaluate_on_dataset",
]
