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
    _check_tracks(p, out)
    return out


def _check_tracks(p: Path, data: dict[str, np.ndarray]) -> None:
    """Shapes and types of a tracks file, checked before any work (no silent casts)."""
    W = data["W"]
    if W.dtype.kind not in "fiu" or W.dtype == bool:
        raise ModelFileError(f"{p}: W must hold real numbers (pixels), got dtype {W.dtype}"
                             + ("; a complex W has no meaning here" if W.dtype.kind == "c" else ""))
    if W.ndim != 2 or W.shape[0] < 2 or W.shape[0] % 2 or W.shape[1] < 1:
        raise ModelFileError(f"{p}: W must be 2F x P (rows u1, v1, u2, v2, ...), got shape {W.shape}")
    F, P = W.shape[0] // 2, W.shape[1]
    data["W"] = W.astype(np.float64)
    if "visible" in data:
        v = data["visible"]
        if v.dtype != bool or v.shape != (F, P):
            raise ModelFileError(f"{p}: visible must be a bool array of shape (F, P) = ({F}, {P}), got "
                                 f"{v.dtype} {v.shape}")
    if "S" in data:
        S = data["S"]
        if S.dtype.kind not in "fiu" or S.dtype == bool or S.shape != (3 * F, P):
            raise ModelFileError(f"{p}: S (ground truth) must be real, of shape (3F, P) = ({3 * F}, {P}), "
                                 "got "
                                 f"{S.dtype} {S.shape}")
        data["S"] = S.astype(np.float64)


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
