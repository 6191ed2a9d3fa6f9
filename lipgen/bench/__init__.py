"""The benchmark suite behind ``lipgen bench``.

Each suite is a module in this package with ``NAME`` and ``run(quick: bool) -> dict``; add it
to ``SUITE_MODULES``. A suite measures its own baseline in the same run (the thesis's dense
inverse, a bare numpy matmul, pyrender's own render, ...) and reports ratios against it,
because these machines are noisy. Results go to one JSON file with the machine and versions.
"""

from __future__ import annotations

import datetime as _dt
import importlib
import logging
import os
import platform
import sys
import time
from importlib import metadata
from pathlib import Path

from lipgen._gitinfo import git_revision
from lipgen._io import atomic_write_json

__all__ = ["SUITE_MODULES", "available_suites", "machine_info", "run_benchmarks"]

log = logging.getLogger(__name__)

SUITE_MODULES: tuple[str, ...] = (
    "lipgen.bench.usd",
    "lipgen.bench.nrsfm",
    "lipgen.bench.physics",
    "lipgen.bench.solvers",
    "lipgen.bench.modes",
    "lipgen.bench.mesh",
    "lipgen.bench.render",
    "lipgen.bench.preset_frames",
    "lipgen.bench.generate_cpu",
    "lipgen.bench.cycles",
    "lipgen.bench.blender",
    "lipgen.bench.startup",
    "lipgen.bench.load",
    "lipgen.bench.campaign",
    "lipgen.bench.speech",
    "lipgen.bench.variance",
    "lipgen.bench.tracking",
)
"""The benchmark suites, one module each, in the order ``lipgen bench`` runs them."""

_PACKAGES = ("lipgen", "numpy", "scipy", "trimesh", "usd-core", "pyrender", "PyOpenGL", "bpy",
             "opencv-python-headless", "pocketsphinx")


def available_suites() -> dict[str, str]:
    """Map suite name to module path, for every registered suite."""
    return {importlib.import_module(m).NAME: m for m in SUITE_MODULES}


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def machine_info() -> dict:
    """Machine, interpreter and package versions, recorded with every benchmark file."""
    versions = {}
    for pkg in _PACKAGES:
        try:
            versions[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            versions[pkg] = None
    return {
        "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "hostname": platform.node(),
        "platform": platform.platform(),
        "machine": platform.machine(),
        "cpu": _cpu_model(),
        "cpu_count": os.cpu_count(),
        "python": sys.version.split()[0],
        "versions": versions,
        "git_revision": git_revision(),
    }


def run_benchmarks(out: str | os.PathLike, suites: list[str] | None = None, quick: bool = False) -> dict:
    """Run the chosen suites (all by default) and write one JSON file to ``out``.

    A suite that fails is recorded with its error and the others still run.
    """
    known = available_suites()
    chosen = list(known) if suites is None else list(suites)  # [] runs none, None runs all
    unknown = [s for s in chosen if s not in known]
    if unknown:
        raise ValueError(f"unknown benchmark suite(s) {unknown}; available: {sorted(known)}")
    result = {"machine": machine_info(), "quick": quick, "suites": {}}
    for name in chosen:
        log.info("bench suite %s", name)
        t0 = time.perf_counter()
        try:
            figures = importlib.import_module(known[name]).run(quick=quick)
            status = "ok"
        except Exception as exc:  # one broken suite must not hide the others' figures
            log.exception("bench suite %s failed", name)
            figures, status = {"error": f"{type(exc).__name__}: {exc}"}, "failed"
        result["suites"][name] = {"status": status, "seconds": time.perf_counter() - t0, **figures}
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_json(out, result)
    return result
