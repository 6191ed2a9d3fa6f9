"""The dataset folder ``lipgen generate`` writes into: a new or empty folder, or the same
dataset to resume; never a folder holding anything else, never through a symlink leading out,
and a killed run's temporaries removed only after those checks."""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

from lipgen._io import remove_stale_temporaries, stale_temporaries
from lipgen.dataset.layout import validate_manifest
from lipgen.errors import DatasetError

__all__ = ["DATASET_PARTS", "check_folder", "check_same_dataset", "prepare_folder", "manifest_differences",
           "SAME_DATASET_KEYS", "is_our_temporary"]

log = logging.getLogger(__name__)


_SUBFOLDERS = ("raw", "truth", "calib", "depth", "masks", "speech")
DATASET_PARTS = ("manifest.json", "mesh.npz", *_SUBFOLDERS)
"""What a dataset or recording folder is made of, beside the video its manifest names."""


def is_our_temporary(p: Path) -> bool:
    """A temporary manifest or mesh left by a killed first run (the folder is still ours to fill)."""
    for name in ("manifest.json", "mesh.npz"):
        if p.name.startswith(f".{name}.tmp-"):
            return p in stale_temporaries(p.parent / name)
    return False


SAME_DATASET_KEYS = ("seed", "settings", "rig", "mesh", "frames", "calibration", "schema_version")
"""The manifest entries two runs must share to write the same dataset."""


def manifest_differences(old: dict, new: dict, keys=SAME_DATASET_KEYS) -> tuple[list[str], str]:
    """The entries of ``keys`` in which manifests ``old`` and ``new`` differ, and a note naming the
    differing settings with their old and new values ("" when the settings agree)."""
    diffs = [k for k in keys if old.get(k) != new.get(k)]
    was, now = old.get("settings", {}), new.get("settings", {})
    detail = "; ".join(f"{k} was {was.get(k)!r}, now {now.get(k)!r}"
                       for k in sorted(set(was) | set(now)) if was.get(k) != now.get(k) and k != "conditions")
    return diffs, detail


def _check_inside(out: Path) -> None:
    """Refuse a dataset whose subfolders or files are symlinks leading out of it: a resume must
    neither write nor delete anything elsewhere."""
    root = out.resolve()
    for name in DATASET_PARTS:
        p = out / name
        if p.is_symlink() and not p.resolve().is_relative_to(root):
            raise DatasetError(f"{p} is a symlink to {p.resolve()}, outside the dataset; refusing to write "
                               "through it (nothing was written). Replace it with a real folder")


def check_folder(out: Path, resume: bool, option: str = "--out") -> dict | None:
    """The checks of ``out`` that need nothing simulated, made before the truth physics runs: a file, a
    folder holding something else, another dataset without ``resume``, an unreadable manifest.
    ``option`` is the command-line option that named ``out``, for the messages.

    Returns the existing manifest (None for a new or empty folder).
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise DatasetError(f"{out} exists and is a file, not a dataset folder; choose another {option}")
    if not (out.is_dir() and any(not is_our_temporary(p) for p in out.iterdir())):
        return None
    mf = out / "manifest.json"
    if not mf.is_file():
        raise DatasetError(f"{out} exists, is not empty and is not a lipgen dataset (no manifest.json); "
                           f"nothing was written. Choose a new or empty folder for {option}")
    if not resume:
        raise DatasetError(f"{out} already holds a dataset; pass --resume to continue it, or choose "
                           "another folder (nothing was overwritten)")
    try:
        old = json.loads(mf.read_text())
    except (OSError, ValueError) as exc:
        raise DatasetError(f"{mf} is not readable JSON ({exc}); cannot resume this folder: remove it or "
                           f"choose another {option}") from exc
    validate_manifest(old, mf)
    return old


def check_same_dataset(out: Path, old: dict, new: dict, option: str = "--out") -> None:
    """Refuse to resume dataset ``out`` (manifest ``old``) as manifest ``new``, or as the entries of
    it given (:func:`lipgen.dataset.manifest.settings_entries`: known before the truth physics runs)."""
    diffs, detail = manifest_differences(old, new, [k for k in SAME_DATASET_KEYS if k in new])
    if diffs:
        raise DatasetError(f"{out} was generated with different settings ({', '.join(diffs)}"
                           f"{': ' + detail if detail else ''}); it is never overwritten: resume only with "
                           f"the same settings, or choose another {option}")


def prepare_folder(out: Path, manifest: dict, resume: bool) -> bool:
    """Create ``out`` or check that it is this very dataset (``resume``); never overwrite another.

    Returns whether ``out`` already held this dataset.
    """
    old = check_folder(out, resume)
    if old is not None:
        check_same_dataset(out, old, manifest)
        _check_inside(out)
        for sub in ("", *_SUBFOLDERS):  # temporary files of writes cut short by a kill
            if (out / sub).is_dir():
                remove_stale_temporaries(out / sub, folder=True)
        return True
    if out.is_dir():  # only a killed first run's temporary manifest is here
        remove_stale_temporaries(out, folder=True)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DatasetError(f"cannot create the dataset folder {out}: {exc.strerror or exc}; choose a "
                           "writable location for --out") from exc
    if not os.access(out, os.W_OK):
        raise DatasetError(f"the dataset folder {out} is not writable; choose another --out")
    return False
