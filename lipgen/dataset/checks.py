"""Checks of what a dataset manifest names: paths that stay inside the folder, numbers that are
numbers, and files that are whole (a cheap decode)."""

from __future__ import annotations

from pathlib import Path, PurePosixPath, PureWindowsPath

import numpy as np

from lipgen._io import load_npz
from lipgen.errors import DatasetError

__all__ = ["check_relative", "intact"]

SCHEMA = 1
"""The dataset schema version every manifest carries."""
FORMAT = "lipgen.dataset"
"""The ``format`` tag of a dataset manifest."""


def _check_number(value, what: str, positive: bool = False) -> float:
    """``value`` as a finite float (positive if asked), else :class:`DatasetError` naming it."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not np.isfinite(value) or (
            positive and value <= 0):
        raise DatasetError(f"{what} must be a {'positive ' if positive else ''}finite number, got {value!r}")
    return float(value)


def check_relative(rel, what: str) -> str:
    """``rel`` if it is a plain relative path inside a dataset folder (no absolute path, no ``..``,
    no drive, no backslash), else :class:`DatasetError` naming it: a manifest never points
    outside its folder."""
    if not isinstance(rel, str) or not rel or "\x00" in rel:
        raise DatasetError(f"{what} must be a relative path inside the dataset folder, got {rel!r}")
    parts = PurePosixPath(rel).parts
    if (PurePosixPath(rel).is_absolute() or PureWindowsPath(rel).is_absolute() or PureWindowsPath(rel).drive
            or "\\" in rel or ".." in parts or rel.startswith("~")):
        raise DatasetError(f"{what} is {rel!r}: paths in a manifest must stay inside the dataset folder "
                           "(relative, without '..'); the manifest was edited or is not trustworthy")
    return rel


def intact(path: Path, kind: str | None = None) -> bool:
    """Whether ``path`` is a complete file: a PNG that decodes, or an npz of ``kind`` that loads.

    A cheap decode catches what a kill or a full disk leaves behind (empty or truncated files),
    so :meth:`Dataset.missing` and ``generate --resume`` redo them.
    """
    path = Path(path)
    try:
        if not path.is_file() or path.stat().st_size == 0:
            return False
        if path.suffix == ".png":
            from PIL import Image

            with Image.open(path) as im:
                im.load()
            return True
        if path.suffix == ".npz":
            if kind is None:
                with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as data:
                    for k in data.files:
                        data[k]
            else:
                load_npz(path, kind, SCHEMA)
            return True
    except Exception:  # noqa: BLE001 - any decoder failure means "redo this file"
        return False
    return True
