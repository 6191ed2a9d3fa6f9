"""Atomic file writes and schema-versioned ``.npz`` archives, shared by every saved type."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import struct
import tempfile
import zipfile
import zlib
from collections.abc import Iterator, Mapping
from pathlib import Path

import numpy as np

from lipgen.errors import ModelFileError

__all__ = ["atomic_path", "atomic_write_bytes", "atomic_savefig", "png_bytes", "atomic_write_json",
           "strict_json", "save_npz", "load_npz", "stale_temporaries", "remove_stale_temporaries"]

_TMP_TAG = ".tmp-"
"""Temporary files are ``.{name}.tmp-{pid}-{random}{suffix}`` beside their destination: the pid
tells a dead writer's leftovers (removed on the next write) from a running writer's."""


def _pid_alive(pid: int) -> bool:
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, another user's
        return True
    return True


def stale_temporaries(dest: str | os.PathLike) -> list[Path]:
    """Temporary files of earlier writes of ``dest`` whose writing process no longer runs.

    Only names this module makes (``.{name}.tmp-{pid}-...``) are matched, so a user's own file
    that merely looks similar (``.manifest.json.tmp-mybackup``) is never touched.
    """
    dest = Path(dest)
    parent = dest.parent if str(dest.parent) else Path(".")
    prefix = f".{dest.name}{_TMP_TAG}"
    out = []
    try:
        entries = list(os.scandir(parent))
    except OSError:
        return out
    for entry in entries:
        if not entry.name.startswith(prefix):
            continue
        pid_text = entry.name[len(prefix):].split("-", 1)[0]
        if pid_text.isdigit() and not _pid_alive(int(pid_text)) and not entry.is_symlink():
            out.append(Path(entry.path))
    return out


def remove_stale_temporaries(dest: str | os.PathLike, folder: bool = False) -> list[Path]:
    """Remove :func:`stale_temporaries` of ``dest`` (a killed writer's leftovers); returns them.

    With ``folder``, ``dest`` is a folder and the stale temporaries of every file in it go.
    """
    if folder:
        stale = []
        with contextlib.suppress(OSError):
            for entry in os.scandir(dest):
                if entry.name.startswith(".") and _TMP_TAG in entry.name:
                    name = entry.name[1:].split(_TMP_TAG, 1)[0]
                    stale += [p for p in stale_temporaries(Path(dest) / name) if p.name == entry.name]
    else:
        stale = stale_temporaries(dest)
    removed = []
    for p in stale:
        with contextlib.suppress(FileNotFoundError):
            if p.is_dir():  # a packager's work folder (usdz)
                shutil.rmtree(p)
            else:
                p.unlink()
            removed.append(p)
    return removed


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None, clean: bool = True) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` only on success.

    A crash or exception leaves the destination untouched and removes the temporary file; the
    leftovers of a writer that was killed (SIGKILL runs no clean-up) are removed by the next
    write of the same destination. ``suffix`` defaults to the destination's own (writers that
    choose a format by extension need it). ``clean=False`` skips that look for leftovers (a scan of
    the folder: a writer of many files into one folder, such as ``generate``, clears them once
    before it starts instead of once per file).
    """
    dest = Path(path)
    parent = dest.parent if str(dest.parent) else Path(".")
    if dest.is_dir():
        raise IsADirectoryError(f"cannot write {dest}: it is a folder; give a file name inside it")
    if not parent.is_dir():
        raise FileNotFoundError(f"cannot write {dest}: folder {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise PermissionError(f"cannot write {dest}: folder {parent} is not writable")
    ext = suffix if suffix is not None else dest.suffix
    if clean:
        remove_stale_temporaries(dest)
    fd, tmp = tempfile.mkstemp(prefix=f".{dest.name}{_TMP_TAG}{os.getpid()}-", suffix=ext, dir=parent)
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


def atomic_write_bytes(path: str | os.PathLike, data: bytes, clean: bool = True) -> None:
    """Write ``data`` to ``path`` atomically (flushed and fsynced before the rename); ``clean``:
    see :func:`atomic_path`."""
    with atomic_path(path, clean=clean) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())


def atomic_savefig(fig, path: str | os.PathLike, **kwargs) -> None:
    """``fig.savefig`` to ``path`` atomically, in the format its suffix names (none: PNG): the
    temporary's own name has no picture suffix for matplotlib to go by."""
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=Path(path).suffix.lstrip(".") or "png", **kwargs)


def strict_json(obj):
    """``obj`` with every NaN or infinity as None (null: strict JSON readers refuse NaN) and numpy
    scalars as Python numbers; dicts, lists and tuples are walked."""
    if isinstance(obj, dict):
        return {k: strict_json(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [strict_json(v) for v in obj]
    if isinstance(obj, float | np.floating):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def atomic_write_json(path: str | os.PathLike, obj) -> None:
    """Write ``obj`` as indented, key-sorted JSON atomically."""
    atomic_write_bytes(path, (json.dumps(obj, indent=2, sort_keys=True) + "\n").encode())


def save_npz(path: str | os.PathLike, kind: str, schema: int, arrays: Mapping[str, np.ndarray],
             compress: bool = True, clean: bool = True) -> None:
    """Save ``arrays`` to ``path`` with a ``kind`` tag and ``schema`` version, atomically.

    Object arrays are refused so that files load without pickle. ``clean``: see :func:`atomic_path`.
    """
    for key, val in arrays.items():
        if np.asarray(val).dtype == object:
            raise TypeError(f"array {key!r} has dtype object; store strings as str arrays")
    payload = {"__kind__": np.array(kind), "__schema__": np.array(schema, dtype=np.int64)}
    payload.update({k: np.asarray(v) for k, v in arrays.items()})
    writer = np.savez_compressed if compress else np.savez
    with atomic_path(path, suffix=".npz", clean=clean) as tmp:
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


_PNG_COLOUR_TYPE = {1: 0, 3: 2, 4: 6}  # channels -> PNG colour type: grey, RGB, RGBA


def _png_chunk(tag: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(data, zlib.crc32(tag)))


def _deflate_module():
    """zlib-ng's zlib-compatible module when installed (``pip install zlib-ng``), else zlib."""
    try:
        from zlib_ng import zlib_ng
    except ImportError:
        return zlib
    return zlib_ng


def png_bytes(image: np.ndarray, level: int) -> bytes:
    """A standard 8-bit PNG file's bytes: every row with PNG's "Up" filter (its difference to the
    row above, mod 256), deflated with the RLE strategy at ``level``, in one IDAT chunk.

    Lossless: any PNG reader decodes the same pixels. The filter is one numpy subtraction rather
    than libpng's per-row choice among five filters (which is most of libpng's time at level 1).
    On a noisy 640x480 frame, against OpenCV's libpng at level 1 with the RLE strategy (the
    encoder before): 0.45x its CPU with zlib, 0.26x with zlib-ng (``lipgen[render]``, used when
    installed: the same size, other bytes), for 1.06x its bytes; a label mask has long runs of
    zeros after the filter and takes a few kB.

    Parameters
    ----------
    image : (H, W), (H, W, 1), (H, W, 3) or (H, W, 4) uint8
        Grey, RGB or RGBA.
    level : int
        zlib compression level, 0 (stored) to 9.

    Returns
    -------
    bytes
    """
    image = np.asarray(image)
    channels = 1 if image.ndim == 2 else (image.shape[2] if image.ndim == 3 else 0)
    if image.dtype != np.uint8 or channels not in _PNG_COLOUR_TYPE or 0 in image.shape[:2]:
        raise ValueError(f"image must be a non-empty (H, W) or (H, W, 1|3|4) uint8 array, got {image.dtype} "
                         f"of shape {image.shape}")
    if isinstance(level, bool) or int(level) != level or not 0 <= level <= 9:
        raise ValueError(f"PNG compression level must be a whole number in [0, 9], got {level!r}")
    h, w = image.shape[:2]
    a = image.reshape(h, w * channels)
    rows = np.empty((h, w * channels + 1), np.uint8)
    rows[:, 0] = 2  # filter type Up
    rows[0, 1:] = a[0]  # the row above the first is zeros
    np.subtract(a[1:], a[:-1], out=rows[1:, 1:])  # uint8: mod 256
    z = _deflate_module()
    deflate = z.compressobj(int(level), z.DEFLATED, 15, 9, z.Z_RLE)
    data = deflate.compress(rows) + deflate.flush()
    header = struct.pack(">IIBBBBB", w, h, 8, _PNG_COLOUR_TYPE[channels], 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", header) + _png_chunk(b"IDAT", data)
            + _png_chunk(b"IEND", b""))
