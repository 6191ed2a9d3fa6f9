"""Interleaved timing: a candidate and its baseline measured round by round, as ratios.

Other processes load these machines and the load drifts within a run. Timing A five times and
then B five times compares A at one load with B at another; timing A, B, A, B ... and taking
the median of the per-round ratios compares them at the same load.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable

import numpy as np

__all__ = ["interleaved", "load_average"]


def load_average() -> list[float]:
    """The 1, 5 and 15 minute load averages (empty where the platform has none)."""
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return []


def interleaved(fns: dict[str, Callable[[], object]], baseline: str, rounds: int = 5,
                warmup: bool = True) -> dict:
    """Time each of ``fns`` once per round, in turn, for ``rounds`` rounds.

    Returns
    -------
    dict
        ``{name: {"median_s", "best_s", "ratio_median"}}`` where ``ratio_median`` is the median
        over rounds of ``time(name) / time(baseline)`` in that round; plus ``rounds`` and
        ``load_average``.
    """
    if baseline not in fns:
        raise ValueError(f"baseline {baseline!r} is not one of the timed functions {sorted(fns)}")
    if rounds < 1:
        raise ValueError(f"rounds must be at least 1, got {rounds}")
    if warmup:
        for fn in fns.values():
            fn()
    times = {name: [] for name in fns}
    for _ in range(rounds):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t0)
    base = np.asarray(times[baseline])
    out: dict = {"rounds": rounds, "baseline": baseline, "load_average": load_average()}
    for name, t in times.items():
        t = np.asarray(t)
        out[name] = {"median_s": float(np.median(t)), "best_s": float(t.min()),
                     "ratio_median": float(np.median(t / base))}
    return out
