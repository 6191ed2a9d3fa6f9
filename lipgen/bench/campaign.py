"""Benchmark suite ``campaign``: Ray campaigns against today's process-pool ``lipgen generate``.

Measured in one run, on the same frames (N items x F frames, generate stage only):

* ``throughput_ratio``: frames/s of a campaign with 2 CPUs over frames/s of
  ``generate(..., workers=2)`` run item after item (the baseline, start-up of its pool included
  as a user pays it); for the embedded Ray (``ray``) and for the local executor (``local``). The
  executor's own start-up is reported apart (``start_s``): a cluster is started once for many
  campaigns; ``throughput_ratio_with_start`` includes it.
* ``task_overhead_ms``: the round trip of an empty task (submit, schedule, return), against
  the median render chunk's duration (``task_overhead_share``).
* ``parallel_efficiency``: the same campaign with 1 CPU and with 2, ``T1 / (2 T2)``.
* ``peak_rss_mib_per_worker``: the largest resident set of a render worker (``ru_maxrss``).
* ``cpu``: CPU seconds (all threads) of the workers, of the driver and (Ray) of Ray's own
  processes, read from ``/proc`` for this process's descendants, with 1 and with 2 CPUs. On a
  shared machine the wall-time efficiency mixes our cost with the scheduler's share, so it is
  split: ``efficiency = work_ratio * busy_ratio``, where ``work_ratio = W1 / W2`` is the worker
  CPU with 1 over with 2 CPUs (extra work that going parallel costs: ours) and
  ``busy_ratio = busy2 / busy1``, ``busy_n = W_n / (n * wall_n)``, how fully the workers were
  kept on the cores (the driver's scheduling, and the other processes' share).
* ``chunk_cost``: in a fresh worker, CPU seconds per frame, of making a renderer (a worker's
  first chunk of a dataset), and of a chunk's fixed cost when the worker goes on to another
  dataset of the same size (the renderer is kept).
* ``model_100_nodes``: the time predicted for M items on 100 nodes of ``cores`` CPUs from the
  measured per-item cost, task overhead and efficiency (see ``predict``).
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from pathlib import Path

import numpy as np

NAME = "campaign"


def predict(items: int, nodes: int, cores: int, item_s: float, efficiency: float, start_s: float,
            driver_task_s: float, tasks_per_item: float) -> float:
    """Seconds for ``items`` items on ``nodes`` x ``cores`` CPUs.

    The items run in waves of ``nodes * cores`` at ``efficiency`` (as measured on one node), plus
    the cluster's start-up and the driver's serial cost of scheduling every task (the part that
    does not shrink with more nodes).
    """
    slots = nodes * cores
    return start_s + math.ceil(items / slots) * item_s / efficiency + items * tasks_per_item * driver_task_s


def _noop() -> int:
    return 0


def _descendants_cpu() -> dict[int, tuple[str, float]]:
    """CPU seconds (user + system, all threads) of every living descendant of this process, by
    pid, with its name (Linux ``/proc``; empty elsewhere)."""
    tick = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    procs: dict[int, tuple[int, str, float]] = {}
    try:
        entries = [d for d in os.listdir("/proc") if d.isdigit()]
    except OSError:
        return {}
    for d in entries:
        try:
            with open(f"/proc/{d}/stat") as fh:
                stat = fh.read()
        except OSError:
            continue
        name, rest = stat[stat.index("(") + 1:stat.rindex(")")], stat[stat.rindex(")") + 2:].split()
        procs[int(d)] = (int(rest[1]), name, (int(rest[11]) + int(rest[12])) / tick)
    me, out = os.getpid(), {}
    for pid, (_, name, cpu) in procs.items():
        p, seen = pid, 0
        while p in procs and p != me and seen < 64:
            p, seen = procs[p][0], seen + 1
        if p == me and pid != me:
            out[pid] = (name, cpu)
    return out


def _is_worker(kind: str, name: str) -> bool:
    """A task process: Ray's workers are titled ``ray::...`` (Ray's own agents too, named
    ``ray::...Agent``); the local executor's workers are the only descendants."""
    if kind != "ray":
        return True
    return name.startswith("ray::") and not name.endswith(("Agent", "agent"))


def _cpu_split(kind: str, before: dict, after: dict, self_cpu: float) -> dict:
    workers = system = 0.0
    for pid, (name, cpu) in after.items():
        prev = before.get(pid)
        delta = cpu - (prev[1] if prev and prev[0] == name else 0.0)
        if _is_worker(kind, name):
            workers += delta
        else:
            system += delta
    return {"workers_s": workers, "ray_system_s": system, "driver_s": self_cpu}


def _campaign_seconds(plan, ex, root: Path, kind: str = "local") -> tuple[float, dict, dict]:
    from lipgen.campaign import run_campaign

    before, c0 = _descendants_cpu(), time.process_time()
    t0 = time.perf_counter()
    index = run_campaign(plan, root, executor=ex, progress=False)
    wall = time.perf_counter() - t0
    cpu = _cpu_split(kind, before, _descendants_cpu(), time.process_time() - c0)
    bad = [e["name"] for e in index["items"] if e["status"] != "done"]
    if bad:
        raise RuntimeError(f"bench campaign items failed: {bad}")
    return wall, index, cpu


def _chunk_cost() -> dict:
    """In this (fresh) worker: CPU seconds of a frame, of making a renderer, and of a chunk's
    fixed cost on a second dataset of the same size (renderer kept)."""
    import tempfile

    from lipgen.campaign.stages import prepare, render_chunk
    from lipgen.dataset.settings import GenerateSettings

    with tempfile.TemporaryDirectory(prefix="lipgen-bench-") as tmp:
        ctxs = []
        for seed in (0, 1):
            s = GenerateSettings(frames=9, size=(320, 240), calib_frames=0, seed=seed)
            ctx, jobs, _ = prepare(f"{tmp}/d{seed}", s.to_dict())
            ctxs.append((ctx, jobs))
        first = render_chunk(ctxs[0][0], ctxs[0][1][:1])["cpu_seconds"]  # makes the renderer
        steady = render_chunk(ctxs[0][0], ctxs[0][1][1:])
        per_frame = steady["cpu_seconds"] / steady["frames"]
        switch = render_chunk(ctxs[1][0], ctxs[1][1][:1])["cpu_seconds"]  # another dataset
    return {"per_frame_cpu_s": per_frame, "new_renderer_cpu_s": first - per_frame,
            "next_dataset_fixed_cpu_s": switch - per_frame}


def _executor(kind: str, cpus: int):
    from lipgen.campaign import LocalExecutor, RayExecutor

    return RayExecutor(num_cpus=cpus, retries=1) if kind == "ray" else LocalExecutor(cpus, retries=1)


def _measure(kind: str, plan, tmp: Path, t_pool: float, quick: bool) -> dict:
    """Throughput, task overhead, 1 vs 2 CPU efficiency and peak memory of one executor kind."""
    out: dict = {}
    times = {}
    for cpus in (2, 1):
        t0 = time.perf_counter()
        ex = _executor(kind, cpus)
        start = time.perf_counter() - t0
        try:
            if cpus == 2:
                ex.result(ex.submit(_noop))  # a warm worker
                rounds = 20 if quick else 100
                t0 = time.perf_counter()
                for _ in range(rounds):
                    h = ex.submit(_noop)
                    while not ex.wait([h], timeout=0.001):
                        pass
                    ex.result(h)
                out["task_overhead_ms"] = 1000 * (time.perf_counter() - t0) / rounds
                t0 = time.perf_counter()
                handles = [ex.submit(_noop) for _ in range(rounds)]
                out["driver_submit_ms"] = 1000 * (time.perf_counter() - t0) / rounds
                [ex.result(h) for h in handles]
            wall, index, cpu = _campaign_seconds(plan, ex, tmp / f"{kind}{cpus}", kind)
        finally:
            ex.shutdown()
        times[cpus] = (start, wall, index)
        cpu["busy"] = cpu["workers_s"] / (cpus * wall)
        out.setdefault("cpu", {})[f"{cpus}cpu"] = cpu
    (start2, wall2, index2), (_, wall1, index1) = times[2], times[1]
    c1, c2 = out["cpu"]["1cpu"], out["cpu"]["2cpu"]
    out["cpu"].update(work_ratio=c1["workers_s"] / c2["workers_s"], busy_ratio=c2["busy"] / c1["busy"],
                      model="efficiency = work_ratio * busy_ratio")
    gen = [e["stages"]["generate"] for e in index2["items"]]
    chunk_s = float(np.median([g["render_seconds"] / g["chunks"] for g in gen]))
    peaks = [e["stages"]["generate"].get("peak_rss_mib") for idx in (index1, index2) for e in idx["items"]]
    peaks = [p for p in peaks if p]
    total = sum(it.settings.frames for it in plan.items)
    eff = wall1 / (2 * wall2)
    item_s = wall1 / len(plan.items)  # one CPU's cost per item, start-up of its workers included
    tasks_per_item = 1 + math.ceil(plan.items[0].settings.frames / plan.chunk_frames)
    submit_s = out["driver_submit_ms"] / 1000
    out.update({
        "start_s": start2,
        "campaign_fps": total / wall2,
        "throughput_ratio": t_pool / wall2,
        "throughput_ratio_with_start": t_pool / (wall2 + start2),
        "median_chunk_s": chunk_s,
        "task_overhead_share": out["task_overhead_ms"] / 1000 / chunk_s,
        "campaign_1cpu_s": wall1, "campaign_2cpu_s": wall2,
        "parallel_efficiency": eff,
        "peak_rss_mib_per_worker": max(peaks) if peaks else None,
        "per_item_cpu_s": item_s,
        "model_100_nodes": {
            "formula": "T = start + ceil(M / (nodes * cores)) * item_s / efficiency "
                       "+ M * tasks_per_item * driver_submit_s",
            "item_s": item_s, "efficiency": eff, "tasks_per_item": tasks_per_item,
            "driver_submit_s": submit_s, "start_s": start2,
            "predicted_s_1000_items_100x2": predict(1000, 100, 2, item_s, eff, start2, submit_s,
                                                    tasks_per_item),
            "predicted_s_1000_items_1x2": predict(1000, 1, 2, item_s, eff, start2, submit_s, tasks_per_item),
            "assumes": "the items fill the slots evenly, the shared folder keeps up with the writes "
                       "(~0.1 MB per frame at 320x240), and the per-node efficiency holds on the cluster",
        },
    })
    return out


def run(quick: bool = False) -> dict:
    from lipgen.campaign import ClusterError, parse_plan
    from lipgen.dataset.generate import generate

    n_items, frames = (4, 12) if quick else (6, 40)
    size = "320x240"
    plan = parse_plan({"base": {"frames": frames, "size": size, "calib_frames": 0},
                       "grid": {"seed": list(range(n_items))},
                       "campaign": {"stages": ["generate"], "chunk_frames": 8}})
    load_before = os.getloadavg()
    out: dict = {"items": n_items, "frames_per_item": frames, "size": size, "chunk_frames": 8}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        for it in plan.items:  # the baseline: today's process pool, item after item
            generate(tmp / "pool" / it.name, it.settings, workers=2, progress=False)
        t_pool = time.perf_counter() - t0
        out["pool_generate_fps"] = n_items * frames / t_pool
        out["local"] = _measure("local", plan, tmp, t_pool, quick)
        from lipgen.campaign import LocalExecutor

        ex = LocalExecutor(1, retries=0)
        try:
            out["chunk_cost"] = ex.result(ex.submit(_chunk_cost))
        finally:
            ex.shutdown()
        per = out["chunk_cost"]["per_frame_cpu_s"]
        out["chunk_cost"]["new_renderer_in_frames"] = out["chunk_cost"]["new_renderer_cpu_s"] / per
        try:
            out["ray"] = _measure("ray", plan, tmp, t_pool, quick)
        except (ClusterError, ImportError) as exc:  # no ray, or a machine too loaded for Ray to start
            out["ray"] = {"error": f"{type(exc).__name__}: {exc}"}
    out.update({"targets": {"throughput_ratio": 0.9, "parallel_efficiency": 0.85},
                "loadavg_before": list(load_before), "loadavg_after": list(os.getloadavg()),
                "cpu_count": os.cpu_count()})
    return out
