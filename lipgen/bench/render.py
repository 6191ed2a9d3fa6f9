"""Benchmark suite ``render``: raw camera-mirror frames per second against pyrender's own limit.

The baseline, measured in the same run and interleaved with the frames, is ONE pyrender render
of the same scene (already uploaded) at the same size through the real camera: the practical
limit of this renderer on this machine. A raw frame costs more: the subject's surfaces and dots
are rebuilt for every frame, uploaded, and the two halves rendered from their own view cameras
and composed (both views in one forward pass, :mod:`lipgen.rig._onepass`; ``two_pass`` is the
same against a renderer that draws one view at a time, in its own interleaved block;
``raw_over_single_*`` are medians of per-round ratios, wall and CPU). ``end_to_end`` adds
encoding the PNG and writing it and a truth file.
``generate_fps`` is the whole ``lipgen generate`` (subject simulation, rendering, sensor noise,
visibility truth, PNG and npz writing) with 1 and 2 worker processes, start-up included;
The hard preset's frames against easy's are suite ``presets``
(:mod:`lipgen.bench.preset_frames`).
``coverage`` and ``frame_parts`` (:mod:`lipgen.bench.frame_parts`):
the pixels a raw frame covers against one pass (the bound they set on ``ratio_to_limit``), its
overdraw (``coverage.overdraw``: samples rasterized and passing the depth test), and the
per-frame sensor noise and visibility truth against their baselines.
"""

from __future__ import annotations

import io
import os
import tempfile
import time
from pathlib import Path

import numpy as np

NAME = "render"


def _frames(mesh, n: int) -> list[np.ndarray]:
    """n different lip shapes (a jaw drop growing frame by frame), so every frame uploads anew."""
    V0 = mesh.vertices
    return [V0 + np.outer(np.clip(-V0[:, 1], 0, 25) * (0.02 * k), [0.0, -1.0, 0.0]) for k in range(n)]


def _two_pass_ratio(rig, face, shapes, reps: int) -> dict:
    """A raw frame rendered a view at a time (``one_pass=False``, the way before issue 22) against
    one pyrender pass, interleaved in its own block: wall and CPU ratios (medians per round)."""
    from lipgen.rig.render import RigRenderer, _View

    width, height = rig.camera.width, rig.camera.height
    walls, cpus = [], []
    with RigRenderer(rig, one_pass=False) as r:
        full = _View(r.pyrender, rig.camera, 20.0, 5000.0)
        r._scene.add_node(full.node)

        def single():
            r._scene.main_camera_node = full.node
            r._renderer.viewport_width, r._renderer.viewport_height = width, height
            return r._renderer.render(r._scene)

        r.render(face.scene(shapes[0]))
        single()
        for k in range(reps):
            c0, t0 = time.process_time(), time.perf_counter()
            r.render(face.scene(shapes[(k + 1) % len(shapes)]))
            c1, t1 = time.process_time(), time.perf_counter()
            single()
            walls.append((t1 - t0) / (time.perf_counter() - t1))
            cpus.append((c1 - c0) / max(time.process_time() - c1, 1e-9))
    return {"raw_over_single_wall": float(np.median(walls)), "raw_over_single_cpu": float(np.median(cpus))}


def run(quick: bool = False) -> dict:
    from PIL import Image

    from lipgen._io import atomic_write_bytes, save_npz
    from lipgen.bench.frame_parts import coverage, frame_parts, overdraw
    from lipgen.dataset.generate import generate
    from lipgen.dataset.layout import GenerateSettings
    from lipgen.mesh.procedural import lip_mesh
    from lipgen.rig.camera import default_rig
    from lipgen.rig.render import RigRenderer, _View
    from lipgen.subject.face import FaceModel

    width, height = 640, 480
    reps = 6 if quick else 30
    mesh = lip_mesh(1)  # the truth subject's resolution
    face = FaceModel(mesh)
    rig = default_rig(width, height)
    shapes = _frames(mesh, 8)
    load_before = os.getloadavg()
    with RigRenderer(rig) as r, tempfile.TemporaryDirectory() as tmp:
        full = _View(r.pyrender, rig.camera, 20.0, 5000.0)  # the whole frame through the real camera
        r._scene.add_node(full.node)

        def raw(k: int):
            return r.render(face.scene(shapes[k % len(shapes)]))

        def single():
            r._scene.main_camera_node = full.node
            r._renderer.viewport_width, r._renderer.viewport_height = width, height
            return r._renderer.render(r._scene)

        def end_to_end(k: int):
            V = shapes[k % len(shapes)]
            frame = r.render(face.scene(V))
            buf = io.BytesIO()
            Image.fromarray(frame.image).save(buf, format="PNG", compress_level=1)
            atomic_write_bytes(Path(tmp) / f"{k:06d}.png", buf.getvalue())
            X, _ = face.marks(V)
            save_npz(Path(tmp) / f"{k:06d}.npz", "bench", 1, {"vertices": V, "uv": rig.project(X)[0]})

        raw(0)
        single()
        end_to_end(0)
        t_raw, t_single, t_e2e, cpu_raw, cpu_single = [], [], [], [], []
        for k in range(reps):  # interleaved, so load changes hit all three alike
            c0, t0 = time.process_time(), time.perf_counter()
            raw(k + 1)
            t_raw.append(time.perf_counter() - t0)
            cpu_raw.append(time.process_time() - c0)
            c0, t0 = time.process_time(), time.perf_counter()
            single()
            t_single.append(time.perf_counter() - t0)
            cpu_single.append(time.process_time() - c0)
            t0 = time.perf_counter()
            end_to_end(k + 1)
            t_e2e.append(time.perf_counter() - t0)
        parts = frame_parts(rig, face, shapes[3], r.render, max(3, reps // 3))
        cov = coverage(r, single, max(3, reps // 3))
        cov["overdraw"] = overdraw(r)
    two_pass = _two_pass_ratio(rig, face, shapes, reps)  # after the first context is closed
    gen = {}
    n_gen = 8 if quick else 40
    for workers in (1, 2):
        with tempfile.TemporaryDirectory() as tmp:
            t0, c0 = time.perf_counter(), time.process_time()
            generate(Path(tmp) / "ds", GenerateSettings(frames=n_gen, calib_frames=0), workers=workers,
                     progress=False)
            gen[f"workers_{workers}"] = n_gen / (time.perf_counter() - t0)
            if workers == 1:  # in this process (its writer thread included)
                gen["workers_1_frames_per_cpu_s"] = n_gen / (time.process_time() - c0)
    med = {name: float(np.median(v)) for name, v in
           (("raw", t_raw), ("single", t_single), ("e2e", t_e2e), ("cpu_raw", cpu_raw))}
    return {
        "size": f"{width}x{height}",
        "mesh_nodes": mesh.n_nodes,
        "repeats": reps,
        "raw_frame_s": med["raw"],
        "raw_frame_cpu_s": med["cpu_raw"],
        "pyrender_single_render_s": med["single"],
        "raw_fps": 1.0 / med["raw"],
        "pyrender_limit_fps": 1.0 / med["single"],
        "ratio_to_limit": med["single"] / med["raw"],
        "raw_over_single_wall": float(np.median(np.asarray(t_raw) / np.asarray(t_single))),
        "raw_over_single_cpu": float(np.median(np.asarray(cpu_raw) / np.maximum(cpu_single, 1e-9))),
        "two_pass": two_pass,
        "coverage": cov,
        "frame_parts": parts,
        "end_to_end_fps": 1.0 / med["e2e"],
        "generate_frames": n_gen,
        "generate_fps": gen,
        "targets": {"ratio_to_limit": 0.5, "end_to_end_fps": 8.0},
        "loadavg_before": list(load_before),
        "loadavg_after": list(os.getloadavg()),
        "cpu_count": os.cpu_count(),
    }
