"""Output checks shared by every command that writes: done before any work, so a run that is
refused (or would fail at its last step) writes nothing and loses nothing.

Rules, the same for every command:

- an existing file is replaced only with ``--force``;
- a file destination must not be a folder, and its folder must exist and be writable (nothing is
  created on the way: a mistyped path fails instead of making folders elsewhere);
- a folder destination (reports) may be new (its parent must exist); an existing folder that
  already holds any of the files the command writes needs ``--force``;
- an input is never replaced, not even with ``--force`` (which replaces outputs): neither an input
  file nor an existing file inside an input folder (a dataset's frames, its mesh).
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

__all__ = ["check_file_output", "check_folder_output", "check_not_input", "check_picture_output", "add_force"]


def add_force(parser, what: str = "--out") -> None:
    """Add the shared ``--force`` flag to ``parser``."""
    parser.add_argument("--force", action="store_true",
                        help=f"replace {what} if it exists (default: refuse and keep the old file)")


def _writable_folder(folder: Path, dest: Path, flag: str) -> None:
    if not folder.is_dir():
        raise FileNotFoundError(f"{flag} {dest}: folder {folder} does not exist; create it first or "
                                "choose another path (nothing was written)")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise PermissionError(f"{flag} {dest}: folder {folder} is not writable; choose another path "
                              "(nothing was written)")


def check_file_output(path, force: bool, flag: str = "--out") -> Path:
    """Check that file ``path`` may be written; returns it as a :class:`Path`.

    Raises
    ------
    IsADirectoryError
        ``path`` is a folder.
    FileExistsError
        ``path`` exists and ``force`` is false.
    FileNotFoundError, PermissionError
        Its folder does not exist or is not writable.
    """
    dest = Path(path)
    if not str(path).strip():
        raise ValueError(f"{flag} is empty; give a file name")
    if dest.is_dir():
        raise IsADirectoryError(f"{flag} {dest} is a folder; give a file name inside it, e.g. "
                                f"{dest / ('out' + (dest.suffix or ''))}")
    if (dest.exists() or dest.is_symlink()) and not force:
        raise FileExistsError(f"{flag} {dest} exists; choose another name or pass --force to replace it")
    _writable_folder(dest.parent if str(dest.parent) else Path("."), dest, flag)
    return dest


def check_folder_output(path, force: bool, products: Iterable[str] = (), flag: str = "--out") -> Path:
    """Check that folder ``path`` may receive the files ``products`` (names inside it).

    A new folder is fine when its parent exists and is writable (the command creates it).
    """
    dest = Path(path)
    if not str(path).strip():
        raise ValueError(f"{flag} is empty; give a folder")
    if dest.exists() and not dest.is_dir():
        raise NotADirectoryError(f"{flag} {dest} is a file, not a folder; choose a folder")
    if not dest.exists():
        _writable_folder(dest.parent if str(dest.parent) else Path("."), dest, flag)
        return dest
    clash = sorted(p for p in products if (dest / p).exists())
    if clash and not force:
        raise FileExistsError(f"{flag} {dest} already holds {', '.join(clash)}; choose another folder or "
                              "pass --force to replace them")
    _writable_folder(dest, dest, flag)
    return dest


def _input_part(folder: Path, rel: Path) -> bool:
    """Whether the existing file ``folder / rel`` is part of input ``folder``: of a dataset or a
    recording (a ``manifest.json``), its manifest, mesh, video and data subfolders; of any other
    folder (chessboard photos, footage), every file."""
    manifest = folder / "manifest.json"
    if not manifest.is_file():
        return True
    from lipgen.dataset.folder import DATASET_PARTS

    parts = set(DATASET_PARTS)
    try:
        import json

        video = json.loads(manifest.read_text()).get("video") or {}
        parts.add(str(video.get("file", "")))
    except (OSError, ValueError, AttributeError):
        pass
    return rel.parts[0] in parts


def check_not_input(path, inputs: Iterable, flag: str = "--out") -> None:
    """Refuse output ``path`` when writing it would replace an input: one of the files ``inputs``
    (paths; None skipped) or an existing file an input folder is made of (:func:`_input_part`: a
    dataset's frames, truth, mesh, manifest; any file of another folder). A command's own earlier
    output inside a dataset (``DATASET/recon.npz``) may be replaced with ``--force``. Symlinks and
    '..' are resolved.

    Raises
    ------
    ValueError
        Naming the input that would be replaced.
    """
    dest = Path(path).resolve()
    for given in inputs:
        if given is None or not str(given).strip():
            continue
        src = Path(given).resolve()
        if dest == src:
            raise ValueError(f"{flag} {path} is the input {given}; writing it would replace the input "
                             "(even with --force); choose another path (nothing was written)")
        if (src.is_dir() and dest.is_relative_to(src) and (dest.exists() or dest.is_symlink())
                and _input_part(src, dest.relative_to(src))):
            raise ValueError(f"{flag} {path} is a file of the input {given} ({dest.relative_to(src)}); "
                             "writing it would change the input (even with --force); choose a path "
                             "outside it (nothing was written)")


def check_picture_output(path, force, flag: str = "--out") -> Path:
    """:func:`check_file_output` for a picture, whose extension must name a format matplotlib writes
    (checked before the drawing, not by ``savefig`` after the work); a name without one is a PNG."""
    dest = check_file_output(path, force, flag)
    from matplotlib.backend_bases import FigureCanvasBase

    formats = FigureCanvasBase.get_supported_filetypes()
    if dest.suffix and dest.suffix.lower().lstrip(".") not in formats:  # no extension: PNG, as before
        raise ValueError(f"{flag} {dest}: a picture's name must end in one of "
                         f"{', '.join('.' + f for f in sorted(formats))}; "
                         f"got {dest.suffix or 'no extension'!r}")
    return dest
