"""Files of ``lipgen nrsfm``: tracks in, shapes out."""

from __future__ import annotations

import os
import zipfile
from pathlib import Path

import numpy as np

from lipgen._io import load_npz, save_npz
from lipgen.errors import ModelFileError
from lipgen.nrsfm.core import Reconstruction

__all__ = ["load_tracks", "save_shapes", "load_shapes", "SHAPES_KIND", "SHAPES_SCHEMA"]

SHAPES_KIND = "nrsfm_shapes"
"""Kind tag of the shapes file ``lipgen nrsfm`` writes."""
SHAPES_SCHEMA = 1
"""Schema version of that file."""


def load_tracks(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a tracks file: ``W`` (2F, P) rows u1, v1, u2, ..., optional ``visible`` (F, P) and ``S``.

    ``S`` (3F, P), when present, is ground truth (as in the benchmark files) and is returned too.

    Raises
    ------
    FileNotFoundError, ModelFileError
        Missing file, unreadable npz, or no ``W`` in it.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"no such tracks file: {p}")
    try:
        with np.load(p, allow_pickle=False) as data:
            out = {k: data[k] for k in data.files if k in ("W", "visible", "S")}
            keys = list(data.files)
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
        raise ModelFileError(f"{p} is not a readable .npz tracks file ({exc})") from exc
    if "W" not in out:
        raise ModelFileError(f"{p} has no array 'W' (2F x P tracks, rows u1, v1, u2, ...); it holds {keys}")
    return out


def save_shapes(path: str | os.PathLike, rec: Reconstruction) -> None:
    """Write a reconstruction atomically: ``S`` (3F, P) camera frame rows x1, y1, z1, x2, ...,
    ``R`` (F, 3, 3), ``weights`` (F, K), ``basis`` (K, 3, P), ``translation`` (F, 2), ``method``,
    ``k``, ``reprojection_rms``."""
    save_npz(path, SHAPES_KIND, SHAPES_SCHEMA, {
        "S": rec.S, "R": rec.rotations, "weights": rec.weights, "basis": rec.basis,
        "translation": rec.translation, "method": np.array(rec.method), "k": np.array(rec.k),
        "reprojection_rms": np.array(rec.reprojection_rms)})


def load_shapes(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a file written by :func:`save_shapes`."""
    return load_npz(path, SHAPES_KIND, SHAPES_SCHEMA, required=("S", "R", "weights", "basis"))
