"""Mode-coefficient curves from files, placed on animation frames.

Two file forms are read:

- **npz** with ``coefficients`` (or ``coef``) ``(F, k)`` and one time base: ``times`` ``(F,)``
  in seconds, ``frames`` ``(F,)`` frame numbers, or a scalar ``fps`` (sample i at i / fps).
  With none of them, sample i is frame ``start + i``.
- **CSV** with a header row. A column named ``time`` (seconds) or ``frame`` gives the time base;
  every other column is one mode, in order. Blank lines and lines starting with ``#`` are skipped.
"""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lipgen._validate import as_float_array

__all__ = ["CoefficientCurves", "load_curves"]

_COEF_KEYS = ("coefficients", "coef")


@dataclass(frozen=True, eq=False)
class CoefficientCurves:
    """Samples of mode coefficients over time.

    Attributes
    ----------
    coefficients : (F, k) float
        One row per sample.
    times : (F,) float or None
        Sample times in seconds, if the file gave them.
    frames : (F,) float or None
        Sample frame numbers, if the file gave them.
    names : tuple of str
        Column names (CSV) or ``("c0", ...)``.
    """

    coefficients: np.ndarray
    times: np.ndarray | None = None
    frames: np.ndarray | None = None
    names: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        C = as_float_array(self.coefficients, "coefficients", (None, None))
        if len(C) == 0 or C.shape[1] == 0:
            raise ValueError(f"coefficient curves need at least one sample and one mode, got {C.shape}")
        object.__setattr__(self, "coefficients", C)
        for name in ("times", "frames"):
            val = getattr(self, name)
            if val is not None:
                arr = as_float_array(val, name, (len(C),))
                if np.any(np.diff(arr) <= 0):
                    i = int(np.flatnonzero(np.diff(arr) <= 0)[0])
                    raise ValueError(f"{name} must increase strictly; sample {i + 1} ({arr[i + 1]}) "
                                     f"does not come after sample {i} ({arr[i]})")
                object.__setattr__(self, name, arr)
        names = tuple(self.names) or tuple(f"c{i}" for i in range(C.shape[1]))
        if len(names) != C.shape[1]:
            raise ValueError(f"{len(names)} names for {C.shape[1]} coefficient columns")
        object.__setattr__(self, "names", names)

    @property
    def n_samples(self) -> int:
        return int(self.coefficients.shape[0])

    @property
    def n_modes(self) -> int:
        return int(self.coefficients.shape[1])

    def frame_numbers(self, fps: float, start_frame: float = 1.0) -> np.ndarray:
        """(F,) frame of each sample: file frames as given, times * fps + start, or start + i."""
        if self.frames is not None:
            return self.frames.copy()
        if self.times is not None:
            if not fps > 0:
                raise ValueError(f"fps must be positive, got {fps}")
            return start_frame + (self.times - self.times[0]) * float(fps)
        return start_frame + np.arange(self.n_samples, dtype=np.float64)


def load_curves(path: str | os.PathLike) -> CoefficientCurves:
    """Read coefficient curves from an ``.npz`` or ``.csv`` file (see the module docstring)."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"no such coefficient file: {p}")
    suffix = p.suffix.lower()
    if suffix == ".npz":
        return _load_npz(p)
    if suffix in (".csv", ".txt"):
        return _load_csv(p)
    raise ValueError(f"{p}: unknown coefficient file type {suffix!r}; use .npz or .csv")


def _load_npz(p: Path) -> CoefficientCurves:
    try:
        with np.load(p, allow_pickle=False) as data:
            d = {k: data[k] for k in data.files}
    except (ValueError, OSError, EOFError) as exc:
        raise ValueError(f"{p} is not a readable npz file: {exc}") from exc
    key = next((k for k in _COEF_KEYS if k in d), None)
    if key is None:
        raise ValueError(f"{p} has no coefficient array: expected one of {_COEF_KEYS}, found "
                         f"{sorted(d)}")
    C = np.asarray(d[key])
    if C.ndim == 1:
        C = C[:, None]
    times = d.get("times")
    frames = d.get("frames")
    if times is None and "fps" in d:
        fps = float(np.asarray(d["fps"]))
        if not fps > 0:
            raise ValueError(f"{p}: fps must be positive, got {fps}")
        times = np.arange(len(C)) / fps
    names = tuple(str(s) for s in d["names"]) if "names" in d else ()
    return CoefficientCurves(C, times, frames, names)


def _load_csv(p: Path) -> CoefficientCurves:
    with open(p, newline="") as fh:
        rows = [r for r in csv.reader(fh) if r and any(c.strip() for c in r)
                and not r[0].lstrip().startswith("#")]
    if len(rows) < 2:
        raise ValueError(f"{p} needs a header row and at least one data row, got {len(rows)} row(s)")
    header = [h.strip() for h in rows[0]]
    try:
        float(header[0])
    except ValueError:
        pass
    else:
        raise ValueError(f"{p}: the first row must be a header (e.g. 'frame,c0,c1'), got numbers "
                         f"{header[:4]}")
    width = len(header)
    body = []
    for i, row in enumerate(rows[1:], start=2):
        if len(row) != width:
            raise ValueError(f"{p} line {i}: {len(row)} values, but the header has {width} columns")
        try:
            body.append([float(c) for c in row])
        except ValueError as exc:
            raise ValueError(f"{p} line {i}: not a number ({exc})") from exc
    A = np.array(body, dtype=np.float64)
    lower = [h.lower() for h in header]
    times = frames = None
    keep = list(range(width))
    for col, name in enumerate(lower):
        if name in ("time", "t", "seconds", "time_s"):
            times = A[:, col]
            keep.remove(col)
            break
        if name in ("frame", "frames"):
            frames = A[:, col]
            keep.remove(col)
            break
    if not keep:
        raise ValueError(f"{p} has a time column but no coefficient columns")
    return CoefficientCurves(A[:, keep], times, frames, tuple(header[c] for c in keep))
