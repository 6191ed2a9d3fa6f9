"""Benchmark suite ``startup``: import time of the command line before it does anything.

``python -X importtime -m lipgen --help`` (and ``nrsfm --help``) against a bare interpreter
(``python -X importtime -c pass``) in the same run, interleaved; the figure is the summed
top-level import time, and the ratio is per round. Target (issue 22): under 0.3 s.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from lipgen.bench.compare import load_average

NAME = "startup"

TARGET_S = 0.3

_CASES = {"python": ["-c", "pass"], "lipgen --help": ["-m", "lipgen", "--help"],
          "lipgen nrsfm --help": ["-m", "lipgen", "nrsfm", "--help"]}


def import_seconds(args: list[str]) -> float:
    """Summed top-level import time (s) that ``python -X importtime ARGS`` reports."""
    out = subprocess.run([sys.executable, "-X", "importtime", *args], capture_output=True, text=True,
                         check=True)
    total = 0
    for line in out.stderr.splitlines():
        if not line.startswith("import time:"):
            continue
        _, cumulative, name = line.split("|")
        if name.startswith(" ") and not name.startswith("  ") and cumulative.strip().isdigit():
            total += int(cumulative)
    return total / 1e6


def run(quick: bool = False) -> dict:
    """Import times of the CLI and of a bare interpreter, interleaved over rounds (JSON-ready)."""
    rounds = 3 if quick else 7
    load = load_average()
    times: dict[str, list[float]] = {name: [] for name in _CASES}
    for _ in range(rounds):
        for name, args in _CASES.items():
            times[name].append(import_seconds(args))
    base = np.asarray(times["python"])
    out: dict = {"load_average_before": load, "load_average_after": load_average(), "rounds": rounds,
                 "target_s": TARGET_S}
    for name, t in times.items():
        t = np.asarray(t)
        out[name] = {"import_median_s": float(np.median(t)), "import_best_s": float(t.min()),
                     "over_bare_python_median": float(np.median(t / base))}
    out["meets_target"] = all(out[n]["import_median_s"] < TARGET_S for n in _CASES if n != "python")
    return out
