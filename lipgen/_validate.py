"""Argument checks shared by every module: they name the bad value and its shape."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["as_float_array", "as_index_array", "check_finite", "check_workers", "MAX_WORKERS"]


def _shape_ok(shape: tuple[int, ...], want: Sequence[int | None]) -> bool:
    return len(shape) == len(want) and all(w is None or s == w for s, w in zip(shape, want, strict=False))


def _fmt(want: Sequence[int | None]) -> str:
    return "(" + ", ".join("*" if w is None else str(w) for w in want) + ("," if len(want) == 1 else "") + ")"


def as_float_array(value, name: str, shape: Sequence[int | None] | None = None,
                   finite: bool = True) -> np.ndarray:
    """``value`` as a float64 array, checked for shape and (optionally) finiteness.

    ``shape`` uses ``None`` for any length, e.g. ``(None, 3)`` for (n, 3).
    """
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be numeric, got {type(value).__name__}: {exc}") from exc
    if shape is not None and not _shape_ok(arr.shape, shape):
        raise ValueError(f"{name} must have shape {_fmt(shape)}, got {arr.shape}")
    if finite:
        check_finite(arr, name)
    return arr


def check_finite(arr: np.ndarray, name: str) -> None:
    """Raise ``ValueError`` naming the first non-finite entry of ``arr``."""
    bad = ~np.isfinite(arr)
    if bad.any():
        first = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ValueError(
            f"{name} has {int(bad.sum())} non-finite value(s) (NaN or inf) in an array of shape "
            f"{arr.shape}; the first is at index {first}"
        )


def as_index_array(value, name: str, upper: int, unique: bool = False,
                   allow_empty: bool = True) -> np.ndarray:
    """``value`` as a 1-D int64 array of indices in ``[0, upper)``.

    Raises ``ValueError`` for out-of-range, repeated (when ``unique``) or non-integer entries.
    """
    arr = np.asarray(value)
    if arr.size == 0:
        if not allow_empty:
            raise ValueError(f"{name} must not be empty")
        return np.zeros(0, dtype=np.int64)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be a 1-D list of indices, got shape {arr.shape}")
    if not np.issubdtype(arr.dtype, np.integer):
        integral = np.issubdtype(arr.dtype, np.floating) and np.all(np.isfinite(arr))
        if integral and np.all(arr == np.round(arr)):
            arr = arr.astype(np.int64)
        else:
            raise TypeError(f"{name} must hold integer indices, got dtype {arr.dtype}")
    arr = arr.astype(np.int64, copy=False)
    out = (arr < 0) | (arr >= upper)
    if out.any():
        raise ValueError(
            f"{name} has {int(out.sum())} index(es) out of range [0, {upper}), e.g. {int(arr[out][0])} "
            f"at position {int(np.flatnonzero(out)[0])}"
        )
    if unique:
        vals, counts = np.unique(arr, return_counts=True)
        if (counts > 1).any():
            raise ValueError(f"{name} repeats index(es) {vals[counts > 1][:5].tolist()}")
    return arr


MAX_WORKERS = 64
"""The most local processes a command starts."""


def check_workers(workers) -> int:
    """``workers`` as a whole number in [1, :data:`MAX_WORKERS`]; ``ValueError`` naming it otherwise."""
    whole = isinstance(workers, int | np.integer) and not isinstance(workers, bool)
    if not whole or not 1 <= workers <= MAX_WORKERS:
        raise ValueError(f"workers must be a whole number in [1, {MAX_WORKERS}], got {workers!r}")
    return int(workers)
