"""Benchmark suite ``cycles``: raw frames from Blender Cycles beside pyrender, in one run.

Both renderers draw the same moving subject (a new lip shape every frame) through the same rig
at the same size, in the same process, interleaved frame by frame: pyrender (the baseline), then
Cycles at each sample count (denoised, all cores). Reported per renderer: the median CPU seconds
per raw frame (``time.process_time``: every thread of the process, so Cycles' and Mesa's worker
threads count) and wall seconds, frames per second, and the median over rounds of the ratio to
pyrender in the same round, with the load average before and after. On a shared machine the CPU
ratio is the figure to compare between runs; wall time follows the load.
"""

from __future__ import annotations

import time

import numpy as np

NAME = "cycles"


def _shapes(mesh, n: int) -> list[np.ndarray]:
    """n different lip shapes (a jaw drop growing frame by frame)."""
    V0 = mesh.vertices
    return [V0 + np.outer(np.clip(-V0[:, 1], 0, 25) * (0.02 * k), [0.0, -1.0, 0.0]) for k in range(n)]


def run(quick: bool = False) -> dict:
    """Seconds per raw frame of Cycles and of pyrender, and their ratios (one interleaved run).

    ``quick``: 160x120, 2 rounds, 4 samples; otherwise 320x240 and 640x480, 4 rounds, 16 and 64
    samples.
    """
    if quick:
        return measure([(160, 120)], [4], 2)
    return measure([(320, 240), (640, 480)], [16, 64], 4)


def measure(sizes: list[tuple[int, int]], sample_counts: list[int], rounds: int) -> dict:
    """The figures of :func:`run` for chosen sizes ``[(w, h), ...]``, Cycles sample counts and
    rounds (after one warm-up round)."""
    from lipgen.bench.compare import load_average
    from lipgen.mesh.procedural import lip_mesh
    from lipgen.rig.camera import default_rig
    from lipgen.rig.cycles import CyclesRenderer
    from lipgen.rig.render import RigRenderer
    from lipgen.subject.face import FaceModel

    face = FaceModel(lip_mesh(1))  # the truth subject's resolution
    shapes = _shapes(face.mesh, 8)
    out: dict = {"load_average_before": load_average(), "rounds": rounds, "baseline": "pyrender",
                 "cycles": {"device": "CPU", "denoise": "OpenImageDenoise", "threads": "all cores"}}
    for w, h in sizes:
        rig = default_rig(w, h)
        names = ["pyrender"] + [f"cycles_{n}" for n in sample_counts]
        cpu = {k: [] for k in names}
        wall = {k: [] for k in names}
        with RigRenderer(rig) as pr:
            renderers = {"pyrender": pr}
            for n in sample_counts:
                renderers[f"cycles_{n}"] = n
            k = 0
            for r in range(rounds + 1):  # round 0 warms up (kernels, EGL, Cycles' first start)
                for name in names:
                    rend = renderers[name]
                    cy = None
                    if not isinstance(rend, RigRenderer):
                        cy = CyclesRenderer(rig, samples=rend)
                        rend = cy
                    try:
                        if cy is not None:
                            rend.render(face.scene(shapes[k % len(shapes)]))  # a first frame: set-up
                        c0, t0 = time.process_time(), time.perf_counter()
                        rend.render(face.scene(shapes[(k + 1) % len(shapes)]))
                        c1, t1 = time.process_time(), time.perf_counter()
                    finally:
                        if cy is not None:
                            cy.close()
                    if r:
                        cpu[name].append(c1 - c0)
                        wall[name].append(t1 - t0)
                k += 1
        base_cpu, base_wall = np.asarray(cpu["pyrender"]), np.asarray(wall["pyrender"])
        per_size = {}
        for name in names:
            c, t = np.asarray(cpu[name]), np.asarray(wall[name])
            per_size[name] = {"cpu_s_per_frame": float(np.median(c)), "wall_s_per_frame": float(np.median(t)),
                              "fps_wall": float(1 / np.median(t)),
                              "cpu_ratio_to_pyrender": float(np.median(c / base_cpu)),
                              "wall_ratio_to_pyrender": float(np.median(t / base_wall))}
        out[f"{w}x{h}"] = per_size
    out["load_average_after"] = load_average()
    return out
