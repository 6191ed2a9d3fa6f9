"""Timing and memory measurement helpers for the benchmark suites."""

from __future__ import annotations

import gc
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path

import numpy as np

__all__ = ["time_call", "peak_memory", "growth_exponent"]


def time_call(fn: Callable[[], object], repeat: int = 5, number: int = 1) -> dict:
    """Wall-clock seconds per call of ``fn``: best and median of ``repeat`` rounds of ``number`` calls."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        times.append((time.perf_counter() - t0) / number)
    return {"best_s": float(np.min(times)), "median_s": float(np.median(times)), "repeat": repeat,
            "number": number}


def _status_kb(field: str) -> int | None:
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1])
    except OSError:
        return None
    return None


def peak_memory(fn: Callable[[], object]) -> tuple[object, dict]:
    """Run ``fn`` once; return its result and the peak memory it added, in MiB.

    On Linux the process's peak resident set (VmHWM) is reset first, so memory allocated in C
    (SuperLU, BLAS) counts too. Elsewhere it falls back to ``tracemalloc`` (Python and numpy
    allocations only), and says which method it used.
    """
    gc.collect()
    try:
        Path("/proc/self/clear_refs").write_text("5")  # resets VmHWM to the current RSS
        base = _status_kb("VmRSS")
    except OSError:
        base = None
    if base is not None:
        result = fn()
        peak = _status_kb("VmHWM")
        return result, {"peak_mib": max(peak - base, 0) / 1024.0, "method": "VmHWM"}
    tracemalloc.start()
    try:
        result = fn()
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return result, {"peak_mib": peak / 2**20, "method": "tracemalloc"}


def growth_exponent(sizes, times) -> float:
    """Least-squares slope of log(time) against log(size): 1 is linear growth."""
    x, y = np.log(np.asarray(sizes, float)), np.log(np.asarray(times, float))
    return float(np.polyfit(x, y, 1)[0])
