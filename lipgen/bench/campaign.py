"""Benchmark suite ``campaign``: Ray campaigns against today's process-pool ``lipgen generate``.

Measured in one run, on the same frames (N items x F frames, generate stage only):

* ``throughput_ratio``: frames/s of a campaign on the embedded Ray with 2 CPUs over frames/s of
  ``generate(..., workers=2)`` run item after item (the baseline, start-up of its pool included
  as a user pays it). Ray's own start-up is reported apart (``ray_start_s``): a cluster is
  started once for many campaigns; ``throughput_ratio_with_start`` includes it.
* ``task_overhead_ms``: the round trip of an empty Ray task (submit, schedule, return), against
  the median render chunk's duration.
* ``parallel_efficiency``: the same campaign on Ray with 1 CPU and with 2, ``T1 / (2 T2)``.
* ``peak_rss_mib_per_worker``: the largest resident set of a render worker (``ru_maxrss``).
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


def _campaign_seconds(plan, ex, root: Path) -> tuple[float, dict]:
    from lipgen.campaign import run_campaign

    t0 = time.perf_counter()
    index = run_campaign(plan, root, executor=ex, progress=False)
    wall = time.perf_counter() - t0
    bad = [e["name"] for e in index["items"] if e["status"] != "done"]
    if bad:
        raise RuntimeError(f"bench campaign items failed: {bad}")
    return wall, index


def run(quick: bool = False) -> dict:
    from lipgen.campaign import RayExecutor, parse_plan
    from lipgen.dataset.generate import generate

    n_items, frames = (4, 12) if quick else (6, 40)
    size = "320x240"
    raw = {"base": {"frames": frames, "size": size, "calib_frames": 0},
           "grid": {"seed": list(range(n_items))},
           "campaign": {"stages": ["generate"], "chunk_frames": 8}}
    plan = parse_plan(raw)
    total = n_items * frames
    load_before = os.getloadavg()
    out: dict = {"items": n_items, "frames_per_item": frames, "size": size, "chunk_frames": 8}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        for it in plan.items:
            generate(tmp / "pool" / it.name, it.settings, workers=2, progress=False)
        t_pool = time.perf_counter() - t0
        times = {}
        for cpus in (2, 1):
            t0 = time.perf_counter()
            ex = RayExecutor(num_cpus=cpus, retries=1)
            start = time.perf_counter() - t0
            try:
                if cpus == 2:
                    ex.result(ex.submit(_noop))  # a warm worker
                    rounds = 20 if quick else 100
                    t0 = time.perf_counter()
                    for _ in range(rounds):
                        ex.result(ex.submit(_noop))
                    out["task_overhead_ms"] = 1000 * (time.perf_counter() - t0) / rounds
                    t0 = time.perf_counter()
                    handles = [ex.submit(_noop) for _ in range(rounds)]
                    out["driver_submit_ms"] = 1000 * (time.perf_counter() - t0) / rounds
                    [ex.result(h) for h in handles]
                wall, index = _campaign_seconds(plan, ex, tmp / f"ray{cpus}")
            finally:
                ex.shutdown()
            times[cpus] = (start, wall, index)
        start2, wall2, index2 = times[2]
        _, wall1, index1 = times[1]
        gen = [e["stages"]["generate"] for e in index2["items"]]
        chunk_s = [g["render_seconds"] / g["chunks"] for g in gen]
        peaks = [g["peak_rss_mib"] for idx in (index1, index2) for e in idx["items"]
                 for g in [e["stages"]["generate"]] if g.get("peak_rss_mib")]
    eff = wall1 / (2 * wall2)
    item_s = wall1 / n_items  # one CPU's cost per item, start-up of the workers included
    tasks_per_item = 1 + math.ceil(frames / 8)
    out.update({
        "pool_generate_fps": total / t_pool,
        "ray_campaign_fps": total / wall2,
        "throughput_ratio": t_pool / wall2,
        "throughput_ratio_with_start": t_pool / (wall2 + start2),
        "ray_start_s": start2,
        "median_chunk_s": float(np.median(chunk_s)),
        "task_overhead_share": out["task_overhead_ms"] / 1000 / float(np.median(chunk_s)),
        "campaign_1cpu_s": wall1, "campaign_2cpu_s": wall2,
        "parallel_efficiency": eff,
        "peak_rss_mib_per_worker": max(peaks) if peaks else None,
        "per_item_cpu_s": item_s,
        "model_100_nodes": {
            "formula": "T = start + ceil(M / (nodes * cores)) * item_s / efficiency "
                       "+ M * tasks_per_item * driver_submit_s",
            "item_s": item_s, "efficiency": eff, "tasks_per_item": tasks_per_item,
            "driver_submit_s": out["driver_submit_ms"] / 1000, "start_s": start2,
            "predicted_s_1000_items_100x2": predict(1000, 100, 2, item_s, eff, start2,
                                                    out["driver_submit_ms"] / 1000, tasks_per_item),
            "predicted_s_1000_items_1x2": predict(1000, 1, 2, item_s, eff, start2,
                                                  out["driver_submit_ms"] / 1000, tasks_per_item),
            "assumes": "the items fit the slots evenly, the shared folder keeps up with the writes "
                       "(~0.1 MB per frame at 320x240), and the per-node efficiency holds on the cluster",
        },
        "targets": {"throughput_ratio": 0.9, "parallel_efficiency": 0.85},
        "loadavg_before": list(load_before), "loadavg_after": list(os.getloadavg()),
        "cpu_count": os.cpu_count(),
    })
    return out
