"""Benchmark suite ``generate``: ``lipgen generate``'s frames per CPU second against an older lipgen.

Issue 22's target is ``generate`` at 1.5x the frames per second per core of the code when the
issue was filed (:data:`BASE_COMMIT`). That code is taken from this checkout's git history
(``git archive``, only its ``lipgen`` package, into a temporary folder). Both trees run the same
``generate`` call (``GenerateSettings(frames=F, calib_frames=0)``: 640x480, ideal camera, noise 1,
PNG level 1) on one worker, the frames per second of one core.

How it is measured, so that the figure is stable on a shared, loaded machine:

- **Interleaved rounds.** Each round runs every tree once, one after the other (never at the same
  time: processes that share the 2 cores slow each other by different amounts), in an order that
  alternates round by round (A B, B A, ...), so drift in the load falls on both.
- **One process per tree and round, three calls in it:** a warm-up of ``frames_short`` frames
  (imports, lazy imports inside ``generate``, shader compilation: one-off costs), then
  ``frames_short`` and ``frames_long`` frames, each timed on its own. The marginal frames per CPU
  second ``(frames_long - frames_short) / (cpu_long - cpu_short)`` cancels everything ``generate``
  pays once per call (the GL context, the set-up), leaving what each further frame costs: the
  subject's motion, the render, the sensor, the truth and the writing.
- **CPU, not wall time:** the process's own and its reaped children's (``getrusage``: user + system,
  every thread). ``LP_NUM_THREADS=1`` in every tree's environment: Mesa's llvmpipe then draws in
  one thread of its own in both (by default it starts one per core and their waiting shows as CPU;
  a tree that sets its own count, as this one does in pool workers, still may).
- **Ratios per round, then the median;** the spread of the per-round ratios (all of them, and
  their quartiles) and the load average are recorded.

Issue 15's target, the ``hard`` preset's ``generate`` at 0.5 of the frames per second of the
default frames when that issue was filed (:data:`ISSUE15_BASE_COMMIT`, whose frame pipeline is
:data:`BASE_COMMIT`'s), is measured after the timed rounds of issue 22, in rounds of its own
(``hard`` against ``base``, the same way): a hard frame is 2-3 times a default one, and in the same
rounds it would weigh on the others' load. The hard run's truth is moved by the linear truth
physics: the nonlinear tissue layer is a one-off simulation (about 0.06 s of CPU per frame) before
any frame is drawn, not the frame pipeline this measures. ``hard_over_new`` divides that figure by
issue 22's median (today's default frames, which ``easy`` reproduces). ``hard_layer`` is the same
run with the hard preset's own nonlinear truth physics, in the same rounds: what a user of
``lipgen generate --preset hard`` waits for per frame.

Without git or the base commit (an installed copy, a shallow clone) the suite says so and skips.

Two baselines: ``base`` is the base code as filed, whose OpenBLAS starts a second thread; its
waiting for work shows as CPU when the other core is free. ``base_one_thread`` is the same code with
one BLAS thread (:data:`ONE_THREAD_ENV`), the stricter baseline. ``wall_ratio`` compares frames per
wall second of the long calls (one worker each: ``base`` then keeps up to two cores busy).

Each run checks that it imported its own tree's ``lipgen``: ``python -c`` puts the working folder
first on ``sys.path``, so before the runs were started in their tree's folder, a bench started
from a checkout's root ran that checkout against itself. Every figure measured before that fix
(1.36-1.78 for issue 22, 0.41-0.56 for issue 15, in earlier notes) is withdrawn.

Measured on a quiet machine (lead, load 0.6-1.6, 7 rounds, 3 for ``hard``; per-round range in
brackets). Issue 22, new over base: 2.60 (2.18-2.84) per CPU second, 1.40 per wall second; over
``base_one_thread``: 1.58 (1.35-1.88) per CPU second, 1.31 per wall second. Issue 15, hard over
base: 0.68 (0.62-0.69) per CPU second, 0.33 per wall second; over ``base_one_thread`` 0.46
(0.44-0.52) and 0.36. The whole suite takes about 4.5 minutes there.

Measured again on 2026-12-06 (2 cores, load 0.1-1.2, the same rounds; the frame pipeline had been
made faster since): new over ``base_one_thread`` 2.72 (2.50-2.85) per CPU second; hard over
``base_one_thread`` 0.78 (0.70-0.84), 0.62 per wall second; ``hard_layer`` over
``base_one_thread`` 0.36 (0.35-0.37), 0.27 per wall second: with its own truth physics a hard
frame costs 0.33 s of CPU, of which about 0.18 s is the tissue layer. The suite took 4 minutes.

After the layer's solver became an L-BFGS from its factorised tangent (the layer's CPU per frame
halved, 0.19 -> 0.10 s on the default seed), three runs later that day, one after another (load
1.0-1.5): ``hard_layer`` over ``base_one_thread`` 0.41 (0.40-0.41), 0.39 (0.33-0.46) and 0.37
(0.36-0.42), against 0.33 (0.30-0.34) and 0.39 (0.36-0.44) for the code before in runs interleaved
with them: the rounds' spread is as large as the change, which the layer's own timing shows better
(``renders/examples/speed33``).

After the layer's tangents were factorised by CHOLMOD with their analysis reused, built in closed
node form, and the layer run on one BLAS thread (0.06 s of CPU per frame, ``renders/examples/speed34``),
four runs one after another (load 1.1-1.9, from the suite itself): ``hard_layer`` over
``base_one_thread`` 0.54 (0.44-0.56), 0.54 (0.50-0.57), 0.56 (0.52-0.59) and 0.52 (0.51-0.59), against
0.37 (0.34-0.40) for the code before, run between the last two; 0.43-0.45 per wall second. On the
final commit, on a quiet machine: 0.54 (0.54-0.54).
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

__all__ = ["BASE_COMMIT", "ISSUE15_BASE_COMMIT", "ONE_THREAD_ENV", "RENDER_ENV", "base_tree", "generate_cpu",
           "spread", "run"]

BASE_COMMIT = "16ccdfc^"
"""The code when issue 22 was filed (its first commit's parent)."""

ISSUE15_BASE_COMMIT = "7546620^"
"""The code when issue 15 was filed (the parent of its first commit, which added the presets). Its
frame pipeline (``lipgen/rig``, ``lipgen/dataset``) differs from :data:`BASE_COMMIT`'s in docstrings
only, so ``base``'s default frames are issue 15's "today's default" too."""

RENDER_ENV = {"LP_NUM_THREADS": "1"}
"""Environment of every tree's runs: llvmpipe draws in one thread of its own."""

ONE_THREAD_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
"""Extra environment of ``base_one_thread``: the base code with one BLAS thread, the fairest baseline
(the base code as filed lets OpenBLAS start a second thread, whose waiting shows as CPU)."""

_DRIVER = """
import json, os, resource, shutil, sys, time
from lipgen.dataset.generate import generate
from lipgen.dataset.layout import GenerateSettings
import lipgen
tree = os.path.realpath(os.environ["PYTHONPATH"])
if not os.path.realpath(lipgen.__file__).startswith(tree + os.sep):
    sys.exit(f"this run imported {lipgen.__file__}, not the lipgen of {tree}")
out, workers, counts = sys.argv[1], int(sys.argv[2]), [int(x) for x in sys.argv[3].split(",")]
preset = os.environ.get("LIPGEN_BENCH_PRESET")
physics = os.environ.get("LIPGEN_BENCH_PHYSICS", "linear")


def cpu():
    return sum(r.ru_utime + r.ru_stime for r in (resource.getrusage(resource.RUSAGE_SELF),
                                                 resource.getrusage(resource.RUSAGE_CHILDREN)))


calls = []
for k, frames in enumerate(counts):
    if preset:  # a preset's frames, its truth moved by the linear physics unless told (module docstring)
        s = GenerateSettings.from_preset(preset, frames=frames, calib_frames=0, truth_physics=physics)
    else:
        s = GenerateSettings(frames=frames, calib_frames=0)
    folder = f"{out}-{k}"
    c0, t0 = cpu(), time.perf_counter()
    generate(folder, s, workers=workers, progress=False)
    calls.append({"frames": frames, "cpu_s": cpu() - c0, "wall_s": time.perf_counter() - t0})
    shutil.rmtree(folder, ignore_errors=True)
print(json.dumps(calls))
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


def _start(tree: Path, out: Path, counts: list[int], workers: int, env: dict | None) -> subprocess.Popen:
    env = dict(os.environ, **(env or {}), PYTHONPATH=str(tree))
    args = [sys.executable, "-c", _DRIVER, str(out), str(workers), ",".join(map(str, counts))]
    # cwd: ``python -c`` puts the working folder first on sys.path, before PYTHONPATH, so run from a
    # checkout's root every tree would import that checkout's lipgen
    return subprocess.Popen(args, env=env, cwd=str(tree), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def _finish(proc: subprocess.Popen, tree: Path) -> list[dict]:
    stdout, stderr = proc.communicate(timeout=3600)
    if proc.returncode != 0:
        raise RuntimeError(f"generate in {tree} failed: {stderr.strip()[-2000:]}")
    return json.loads(stdout.strip().splitlines()[-1])


def _runs(trees: dict[str, Path], envs: dict, tmp: Path, tag: str, counts: list[int],
          workers: int) -> dict[str, list[dict]]:
    """One process per tree, each making ``generate`` calls of ``counts`` frames in turn, the trees
    one after the other in the order given (never at once: they would share the cores). Returns per
    tree the calls' ``{"frames", "cpu_s", "wall_s"}``."""
    return {n: _finish(_start(trees[n], tmp / f"{n}-{tag}", counts, workers, envs.get(n)), trees[n])
            for n in trees}


def spread(values) -> dict:
    """Median, quartiles and range of ``values`` (1-D): how far a suite's per-round ratios scatter."""
    v = np.asarray(values, float)
    q1, med, q3 = np.percentile(v, [25, 50, 75])
    return {"median": float(med), "quartiles": [float(q1), float(q3)],
            "range": [float(v.min()), float(v.max())], "rounds": [float(x) for x in v]}


def generate_cpu(trees: dict[str, Path], baseline: str, workers: int, frames_short: int, frames_long: int,
                 rounds: int, envs: dict[str, dict] | None = None, warmup: bool = True) -> dict:
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
        Frames of the two timed calls per round and tree (``frames_long > frames_short``).
    rounds : int
        Rounds; each starts one process per tree, one after the other, in an order that reverses
        round by round.
    envs : dict of str to dict, optional
        Extra environment variables of a name's runs.
    warmup : bool
        Begin each process with an untimed call of ``frames_short`` frames (one-off costs).

    Returns
    -------
    dict
        Per name: median ``frames_per_cpu_s`` (marginal), ``whole_call_frames_per_cpu_s`` and
        ``frames_per_wall_s`` (the long call), and ``per_round`` (the marginal and wall rates of each
        round); and for the others ``ratio`` (marginal, median of the per-round ratios),
        ``ratio_spread`` (:func:`spread`), ``whole_call_ratio`` and ``wall_ratio`` (frames per wall
        second of the long calls); plus ``load_average`` before and after.
    """
    if baseline not in trees:
        raise ValueError(f"baseline {baseline!r} is not one of the trees {sorted(trees)}")
    if not frames_long > frames_short >= 1:
        raise ValueError(f"need frames_long > frames_short >= 1, got {frames_long}, {frames_short}")
    if isinstance(rounds, bool) or int(rounds) != rounds or rounds < 1:
        raise ValueError(f"rounds must be a whole number >= 1, got {rounds!r}")
    counts = ([frames_short] if warmup else []) + [frames_short, frames_long]
    per = {name: {"marginal": [], "whole": [], "wall": []} for name in trees}
    load_before = load_average()
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(int(rounds)):
            order = dict(list(trees.items())[:: 1 if r % 2 == 0 else -1])
            calls = _runs(order, envs or {}, Path(tmp), str(r), counts, workers)
            for name in trees:
                short, long = calls[name][-2:]
                extra = max(long["cpu_s"] - short["cpu_s"], 1e-9)
                per[name]["marginal"].append((frames_long - frames_short) / extra)
                per[name]["whole"].append(frames_long / long["cpu_s"])
                per[name]["wall"].append(frames_long / long["wall_s"])
    out: dict = {"workers": workers, "frames": [frames_short, frames_long], "rounds": int(rounds),
                 "warmup": warmup, "load_average": [load_before, load_average()]}
    base = {k: np.asarray(v) for k, v in per[baseline].items()}
    for name, v in per.items():
        row = {"frames_per_cpu_s": float(np.median(v["marginal"])),
               "whole_call_frames_per_cpu_s": float(np.median(v["whole"])),
               "frames_per_wall_s": float(np.median(v["wall"])),
               "per_round": {"marginal": [float(x) for x in v["marginal"]],
                             "wall": [float(x) for x in v["wall"]]}}
        if name != baseline:
            ratios = np.asarray(v["marginal"]) / base["marginal"]
            row |= {"ratio": float(np.median(ratios)), "ratio_spread": spread(ratios),
                    "whole_call_ratio": float(np.median(np.asarray(v["whole"]) / base["whole"])),
                    "wall_ratio": float(np.median(np.asarray(v["wall"]) / base["wall"]))}
        out[name] = row
    return out


def run(quick: bool = False) -> dict:
    """The suite: this tree's default frames against :data:`BASE_COMMIT`'s (issue 22), then its
    ``hard`` frames against the same (issue 15), one worker (see the module docstring)."""
    here = Path(__file__).resolve().parents[2]
    frames_short, frames_long = (2, 8) if quick else (6, 36)
    rounds, hard_rounds = (1, 1) if quick else (7, 3)
    with tempfile.TemporaryDirectory() as tmp:
        base = base_tree(Path(tmp) / "base")
        if base is None:
            return {"skipped": f"no git history holding {BASE_COMMIT} beside {here}"}
        envs = {"base": RENDER_ENV, "base_one_thread": RENDER_ENV | ONE_THREAD_ENV, "new": RENDER_ENV,
                "hard": RENDER_ENV | {"LIPGEN_BENCH_PRESET": "hard"},
                "hard_layer": RENDER_ENV | {"LIPGEN_BENCH_PRESET": "hard", "LIPGEN_BENCH_PHYSICS": "layer"}}
        trees = {"base": base, "base_one_thread": base}
        new = generate_cpu(trees | {"new": here}, "base", 1, frames_short, frames_long, rounds, envs=envs)
        hard = generate_cpu(trees | {"hard": here, "hard_layer": here}, "base", 1, frames_short, frames_long,
                            hard_rounds, envs=envs)
    return {"base_commit": BASE_COMMIT, "issue15_base_commit": ISSUE15_BASE_COMMIT, "render_env": RENDER_ENV,
            "new_over_base": new, "hard_over_base": hard,
            "new_over_base_one_thread": _over(new, "new", "base_one_thread"),
            "hard_over_base_one_thread": _over(hard, "hard", "base_one_thread"),
            "hard_layer_over_base_one_thread": _over(hard, "hard_layer", "base_one_thread"),
            "hard_over_new": hard["hard"]["ratio"] / new["new"]["ratio"],
            "targets": {"new_over_base": 1.5, "hard_over_base": 0.5}}


def _over(result: dict, name: str, baseline: str) -> dict:
    """Median and spread of ``name``'s per-round marginal (CPU) and wall rates over ``baseline``'s,
    from one :func:`generate_cpu` result that ran both."""
    cpu = (np.asarray(result[name]["per_round"]["marginal"])
           / np.asarray(result[baseline]["per_round"]["marginal"]))
    wall = np.asarray(result[name]["per_round"]["wall"]) / np.asarray(result[baseline]["per_round"]["wall"])
    return {"ratio": float(np.median(cpu)), "ratio_spread": spread(cpu), "wall_ratio": float(np.median(wall))}
