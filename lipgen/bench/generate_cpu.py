"""Benchmark suite ``generate``: ``lipgen generate``'s frames per CPU second against an older lipgen.

Issue 22's target is ``generate`` at 1.5x the frames per second per core of the code when the
issue was filed (:data:`BASE_COMMIT`). That code is taken from this checkout's git history
(``git archive``, only its ``lipgen`` package, into a temporary folder), and both trees run the
same ``generate`` call in fresh subprocesses started at the same time, so both see the same load
(the load of a shared machine drifts by more than the differences measured), round after round,
on the default settings (``GenerateSettings(frames=F, calib_frames=0)``: 640x480, ideal camera,
noise 1, PNG level 1), with 1 and with 2 worker processes.

Issue 15's target is the ``hard`` preset's ``generate`` at 0.5 of the frames per second of the
default frames when that issue was filed (:data:`ISSUE15_BASE_COMMIT`, whose frame pipeline is
:data:`BASE_COMMIT`'s). So each round also runs this tree with ``--preset hard`` (``hard``), at the
same moment as the other two, and the suite reports ``hard`` over ``base`` (issue 15's figure) and
over ``new`` (``hard_over_new``: against today's default frames, which ``easy`` reproduces). The
hard run's truth is moved by the linear truth physics: the nonlinear tissue layer is a one-off
simulation of seconds per frame before any frame is drawn, not the frame pipeline this measures.

CPU is the subprocess's own and its reaped children's (``getrusage``: user + system, every
thread and pool worker), so a writer thread or a second worker shows as CPU, not as speed.
Per round and tree, two runs of ``frames_short`` and ``frames_long`` frames give

- ``frames_per_cpu_s``: the marginal frames per CPU second,
  ``(frames_long - frames_short) / (cpu_long - cpu_short)`` (start-up, simulation and the GL
  context cancel out): what each further frame costs;
- ``whole_run_frames_per_cpu_s``: ``frames_long / cpu_long`` (start-up included, as a user pays it).

The ratios are new over base per round, and their medians; the load average is recorded.
Without git or the base commit (an installed copy, a shallow clone) the suite says so and skips.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from lipgen.bench.compare import load_average

NAME = "generate"

__all__ = ["BASE_COMMIT", "base_tree", "generate_cpu", "run"]

BASE_COMMIT = "16ccdfc^"
"""The code when issue 22 was filed (its first commit's parent)."""

ISSUE15_BASE_COMMIT = "7546620^"
"""The code when issue 15 was filed (the parent of its first commit, which added the presets). Its
frame pipeline (``lipgen/rig``, ``lipgen/dataset``) differs from :data:`BASE_COMMIT`'s in docstrings
only, so ``base``'s default frames are issue 15's "today's default" too."""

_DRIVER = """
import json, os, resource, sys, time
from lipgen.dataset.generate import generate
from lipgen.dataset.layout import GenerateSettings
out, frames, workers = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
preset = os.environ.get("LIPGEN_BENCH_PRESET")
if preset:  # a preset's frames, its truth moved by the linear physics (see the module docstring)
    s = GenerateSettings.from_preset(preset, frames=frames, calib_frames=0, truth_physics="linear")
else:
    s = GenerateSettings(frames=frames, calib_frames=0)
t0 = time.perf_counter()
generate(out, s, workers=workers, progress=False)
wall = time.perf_counter() - t0
cpu = sum(r.ru_utime + r.ru_stime for r in (resource.getrusage(resource.RUSAGE_SELF),
                                             resource.getrusage(resource.RUSAGE_CHILDREN)))
print(json.dumps({"cpu_s": cpu, "wall_s": wall}))
"""


def base_tree(dest: str | os.PathLike, commit: str = BASE_COMMIT) -> Path | None:
    """Extract ``commit``'s ``lipgen`` package from this checkout's git history into ``dest``.

    Returns ``dest`` (to put on ``PYTHONPATH``), or None when there is no git checkout holding
    that commit.
    """
    repo = Path(__file__).resolve().parents[2]
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    try:
        archive = subprocess.run(["git", "-C", str(repo), "archive", commit, "lipgen"], capture_output=True,
                                 timeout=120, check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(dest)], input=archive, capture_output=True, timeout=120,
                       check=True)
    except (OSError, subprocess.SubprocessError):
        return None
    return dest


def _start(tree: Path, out: Path, frames: int, workers: int, env: dict | None) -> subprocess.Popen:
    env = dict(os.environ, **(env or {}), PYTHONPATH=str(tree))
    return subprocess.Popen([sys.executable, "-c", _DRIVER, str(out), str(frames), str(workers)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _finish(proc: subprocess.Popen, tree: Path) -> dict:
    stdout, stderr = proc.communicate(timeout=3600)
    if proc.returncode != 0:
        raise RuntimeError(f"generate in {tree} failed: {stderr.strip()[-2000:]}")
    return json.loads(stdout.strip().splitlines()[-1])


def _runs(trees: dict[str, Path], envs: dict, tmp: Path, tag: str, frames: int, workers: int,
          together: bool) -> dict[str, dict]:
    """One run of every tree: all at once (``together``: the same load for each), or one by one."""
    names = list(trees)
    if together:
        procs = {}
        try:
            for n in names:
                procs[n] = _start(trees[n], tmp / f"{n}-{tag}", frames, workers, envs.get(n))
            return {n: _finish(p, trees[n]) for n, p in procs.items()}
        finally:  # an error or Ctrl-C in one run: the others do not run on
            for p in procs.values():
                if p.poll() is None:
                    p.kill()
                    p.wait()
    return {n: _finish(_start(trees[n], tmp / f"{n}-{tag}", frames, workers, envs.get(n)), trees[n])
            for n in names}


def generate_cpu(trees: dict[str, Path], baseline: str, workers: int, frames_short: int, frames_long: int,
                 rounds: int, envs: dict[str, dict] | None = None, together: bool = True) -> dict:
    """Frames per CPU second of ``generate`` in each of ``trees``, interleaved, and ratios to ``baseline``.

    Parameters
    ----------
    trees : dict of str to Path
        Name -> folder holding a ``lipgen`` package (put first on ``PYTHONPATH``).
    baseline : str
        The name in ``trees`` the ratios are taken against.
    workers : int
        ``generate``'s worker processes.
    frames_short, frames_long : int
        Frames of the two runs per round (``frames_long > frames_short``).
    rounds : int
        Rounds; each runs every tree twice.
    envs : dict of str to dict, optional
        Extra environment variables of a name's runs.
    together : bool
        Start the trees' runs of a round at the same time, so that each sees the same load (the
        machine's load drifts by more than the differences measured); else one after the other,
        in an order that alternates round by round.

    Returns
    -------
    dict
        Per name: median ``frames_per_cpu_s`` (marginal), ``whole_run_frames_per_cpu_s`` and
        ``frames_per_wall_s`` (long run); and for the others ``ratio`` (marginal, per-round median),
        ``ratio_rounds`` and ``whole_run_ratio``; ``load_average`` before and after.
    """
    if not frames_long > frames_short >= 1:
        raise ValueError(f"need frames_long > frames_short >= 1, got {frames_long}, {frames_short}")
    per = {name: {"marginal": [], "whole": [], "wall": []} for name in trees}
    load_before = load_average()
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(rounds):
            order = dict(list(trees.items())[:: 1 if r % 2 == 0 else -1])
            short = _runs(order, envs or {}, Path(tmp), f"{r}-s", frames_short, workers, together)
            long = _runs(order, envs or {}, Path(tmp), f"{r}-l", frames_long, workers, together)
            for name in trees:
                extra = max(long[name]["cpu_s"] - short[name]["cpu_s"], 1e-9)
                per[name]["marginal"].append((frames_long - frames_short) / extra)
                per[name]["whole"].append(frames_long / long[name]["cpu_s"])
                per[name]["wall"].append(frames_long / long[name]["wall_s"])
    out: dict = {"workers": workers, "frames": [frames_short, frames_long], "rounds": rounds,
                 "together": together, "load_average": [load_before, load_average()]}
    base = {k: np.asarray(v) for k, v in per[baseline].items()}
    for name, v in per.items():
        row = {"frames_per_cpu_s": float(np.median(v["marginal"])),
               "whole_run_frames_per_cpu_s": float(np.median(v["whole"])),
               "frames_per_wall_s": float(np.median(v["wall"]))}
        if name != baseline:
            ratios = np.asarray(v["marginal"]) / base["marginal"]
            row |= {"ratio": float(np.median(ratios)), "ratio_rounds": [float(x) for x in ratios],
                    "whole_run_ratio": float(np.median(np.asarray(v["whole"]) / base["whole"]))}
        out[name] = row
    return out


def hard_over_new(result: dict) -> dict:
    """Issue 15's figure beside issue 22's from one :func:`generate_cpu` result holding ``base``,
    ``new`` and ``hard``: hard over the current default frames, per round (``base`` cancels) and
    median; hard over the base's default frames is ``result["hard"]["ratio"]``."""
    per = np.asarray(result["hard"]["ratio_rounds"]) / np.asarray(result["new"]["ratio_rounds"])
    return {"ratio": float(np.median(per)), "ratio_rounds": [float(x) for x in per]}


def run(quick: bool = False) -> dict:
    """The suite: this tree (default and ``hard`` frames) against :data:`BASE_COMMIT`'s default
    frames, 1 and 2 workers (see the module docstring)."""
    here = Path(__file__).resolve().parents[2]
    frames_short, frames_long, rounds = (4, 12, 1) if quick else (8, 48, 3)
    with tempfile.TemporaryDirectory() as tmp:
        base = base_tree(Path(tmp) / "base")
        if base is None:
            return {"skipped": f"no git history holding {BASE_COMMIT} beside {here}"}
        trees = {"base": base, "new": here, "hard": here}
        envs = {"hard": {"LIPGEN_BENCH_PRESET": "hard"}}
        out: dict = {"base_commit": BASE_COMMIT, "issue15_base_commit": ISSUE15_BASE_COMMIT}
        for w in (1, 2):
            res = generate_cpu(trees, "base", w, frames_short, frames_long, rounds, envs=envs)
            out[f"workers_{w}"] = res | {"hard_over_new": hard_over_new(res)}
        return out
