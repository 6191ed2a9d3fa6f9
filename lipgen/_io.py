"""Atomic file writes and schema-versioned ``.npz`` archives, shared by every saved type."""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
import zipfile
from collections.abc import Iterator, Mapping
from pathlib import Path

import numpy as np

from lipgen.errors import ModelFileError

__all__ = ["atomic_path", "atomic_write_bytes", "atomic_write_json", "save_npz", "load_npz"]


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` only on success.

    A crash or exception leaves the destination untouched and removes the temporary file.
    ``suffix`` defaults to the destination's own (writers that choose a format by extension
    need it).
    """
    dest = Path(path)
    parent = dest.parent if str(dest.parent) else Path(".")
    if not parent.is_dir():
        raise FileNotFoundError(f"cannot write {dest}: folder {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise PermissionError(f"cannot write {dest}: folder {parent} is not writable")
    ext = suffix if suffix is not None else dest.suffix
    fd, tmp = tempfile.mkstemp(prefix=f".{dest.name}.tmp-", suffix=ext, dir=parent)
    os.close(fd)
    tmp_path = Path(tmp)
    os.chmod(tmp_path, 0o666 & ~_umask())  # mkstemp makes 0600; final files get normal permissions
    try:
        yield tmp_path
        os.replace(tmp_path, dest)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (flushed and fsynced before the rename)."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())


def atomic_write_json(path: str | os.PathLike, obj) -> None:
    """Write ``obj`` as indented, key-sorted JSON atomically."""
    atomic_write_bytes(path, (json.dumps(obj, indent=2, sort_keys=True) + "\n").encode())


def save_npz(path: str | os.PathLike, kind: str, schema: int, arrays: Mapping[str, np.ndarray],
             compress: bool = True) -> None:
    """Save ``arrays`` to ``path`` with a ``kind`` tag and ``schema`` version, atomically.

    Object arrays are refused so that files load without pickle.
    """
    for key, val in arrays.items():
        if np.asarray(val).dtype == object:
            raise TypeError(f"array {key!r} has dtype object; store strings as str arrays")
    payload = {"__kind__": np.array(kind), "__schema__": np.array(schema, dtype=np.int64)}
    payload.update({k: np.asarray(v) for k, v in arrays.items()})
    writer = np.savez_compressed if compress else np.savez
    with atomic_path(path, suffix=".npz") as tmp:
        with open(tmp, "wb") as fh:
            writer(fh, **payload)
            fh.flush()
            os.fsync(fh.fileno())


def load_npz(path: str | os.PathLike, kind: str, schema: int,
             required: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    """Load a file written by :func:`save_npz`, checking its kind, schema and keys.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ModelFileError
        If the file is not a readable npz, is of another kind or schema, or lacks a key.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"no such file: {p}")
    try:
        # our own handle: np.load leaks its file when the zip is corrupt
        with open(p, "rb") as fh, np.load(fh, allow_pickle=False) as data:
            out = {k: data[k] for k in data.files}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
        raise ModelFileError(
            f"{p} is not a readable lipgen {kind} file (corrupt or truncated npz: {exc})"
        ) from exc
    got_kind = str(out.pop("__kind__", "?"))
    got_schema = int(out.pop("__schema__", -1))
    if got_kind != kind:
        raise ModelFileError(f"{p} holds a {got_kind!r}, not a {kind!r}")
    if got_schema != schema:
        raise ModelFileError(
            f"{p} is a {kind} of schema version {got_schema}; this lipgen reads version {schema}. "
            "Re-create the file with this version of lipgen."
        )
    missing = [k for k in required if k not in out]
    if missing:
        raise ModelFileError(f"{p} is missing field(s) {missing} of a {kind} file")
    return out
