"""Checks of a reconstruction file's arrays as read from disk (:meth:`Reconstruction.load`): an
altered or foreign file is named with the array, its shape and the fix, not met later as a
traceback or a model silently trained on fewer frames."""

from __future__ import annotations

import numpy as np

from lipgen.errors import ModelFileError

__all__ = ["check_recon_arrays", "MAX_FIELD_MM"]

MAX_FIELD_MM = 1e4
"""Largest displacement a reconstruction may hold, mm (lips move millimetres; 10 m is no field)."""

_SHAPES = {"markers": ("F", None, 3), "visible": ("F", None), "lab_points": ("F", None, 3),
           "ray_gap": ("F", None), "uv": (2, "F", None, 2), "status": (2, "F", None),
           "score": (2, "F", None), "frame_index": ("F",), "rotations": ("F", 3, 3),
           "lab_to_board": (4, 4), "similarity": (4, 4)}
"""Each array's shape: "F" the frames of ``fields``, None any length."""


def _refuse(path, what: str):
    raise ModelFileError(f"{path}: {what}; the file was altered or is not a lipgen reconstruction. "
                         "Reconstruct it again (lipgen reconstruct)")


def check_recon_arrays(path, d: dict) -> None:
    """Refuse arrays ``d`` (name -> array) that disagree in shape or type, or ``fields`` (F, n, 3)
    holding inf, a frame NaN only in part (NaN marks a whole frame without a field) or values
    beyond :data:`MAX_FIELD_MM`."""
    f = d["fields"]
    if not np.issubdtype(f.dtype, np.floating) or f.ndim != 3 or f.shape[2] != 3 or len(f) == 0:
        _refuse(path, f"fields must be float (F, n, 3) with F >= 1 frames, got {f.dtype} {f.shape}")
    F = len(f)
    for name, want in _SHAPES.items():
        a, shape = d[name], tuple(F if w == "F" else w for w in want)
        if a.ndim != len(shape) or any(w is not None and s != w for s, w in zip(a.shape, shape, strict=True)):
            text = "(" + ", ".join("*" if w is None else str(w) for w in shape) + ")"
            _refuse(path, f"{name} has shape {a.shape}, expected {text} for the {F} frames of fields")
        if not (np.issubdtype(a.dtype, np.number) or a.dtype == bool):
            _refuse(path, f"{name} holds {a.dtype}, not numbers")
    for name in ("lab_to_board", "similarity"):
        if not np.isfinite(d[name]).all():
            _refuse(path, f"{name} {d[name].shape} holds NaN or inf")
    finite = np.isfinite(f.reshape(F, -1))
    partial = np.flatnonzero(finite.any(axis=1) & ~finite.all(axis=1))
    if np.isinf(f).any() or len(partial):
        frame = int(np.flatnonzero(np.isinf(f).any(axis=(1, 2)))[0]) if np.isinf(f).any() else int(partial[0])
        _refuse(path, f"fields {f.shape} holds inf or NaN in part of a frame (first: frame {frame}); only a "
                "whole frame may be NaN (no field)")
    top = float(np.abs(f[finite.all(axis=1)]).max(initial=0.0))
    if top > MAX_FIELD_MM:
        _refuse(path, f"fields {f.shape} reach {top:.3g} mm, beyond {MAX_FIELD_MM:g} mm")
