"""Benchmark suite ``presets``: generate's per-frame work under ``--preset hard`` against ``easy``.

Issue 15's speed target: ``hard`` frames at no less than half of ``easy``'s (today's default)
frames per second with pyrender. Both presets film the same moving subject: the hard preset's
motion (its head motion and independent speech sources), simulated once with the linear truth
physics, since the nonlinear tissue layer of ``hard`` is a one-off simulation before any frame is
rendered (about 0.06 s of CPU per frame, not part of the frame pipeline). Each worker is set up as
``generate`` sets up its own (one BLAS thread, one GL context per preset), and the frames are
interleaved: easy frame i, hard frame i, easy frame i + 1, ... Each frame is the whole per-frame
job: render (every sub-frame instant of the exposure), form (lens, mirror, sensor, JPEG),
truth, PNG and npz writing.

Figures: ``hard_over_easy_fps``, the median over frames of ``cpu(easy) / cpu(hard)`` (CPU time
of this process: the GL rasterizer runs in it), with the wall-clock ratio beside it; the CPU
seconds per frame of each; the renders per hard frame (motion blur instants); and
``shadow_filter``: one shadowed render of the hard scene with lipgen's 16-read shadow filter
(:mod:`lipgen.rig._shadowmap`) over pyrender's own 36-read one, interleaved, CPU; and
``face_cost``: where a hard render's CPU goes, as ratios to the whole render, interleaved: without
the ``face`` item (the lips and the head round them, most of the scene's triangles), with its
triangles turned away from the cameras (culled before rasterization: its vertex work stays), and
with each of its triangles split in four (the same surface and pixels, four times the triangles).
On llvmpipe the last two say whether the head costs by its pixels or by its triangles.
``msaa``: one hard render without multisampling over one with pyrender's 4 samples (CPU,
interleaved), and how far that moves the render's face pixels (RMS, largest, share over 3 grey
levels; before the lens and the sensor). ``fidelity``: how far the hard preset's blur instants and
head mesh move its frames against dense references, beside the sensor's noise
(:mod:`lipgen.bench.preset_fidelity`).

Measured (2 cores, load 8, main at c7c70a3): hard/easy 0.29 CPU (0.21-0.25 wall); 0.47 s CPU
per hard frame of which about 0.45 s is 1.75 renders; in one hard render, without the ``face``
item 0.30, its triangles culled 0.34, split in four 2.0 (12,144 of the scene's 22,216
triangles): on llvmpipe each front-facing triangle costs about 2.5 us per pass (two views and
the shadow map), and the ``face`` item's pixels and triangles cost about the same. The draw order
of the items changes neither the pixels nor the CPU (no overdraw to save), and one light instead
of three or no skin texture changes the CPU by under 3 %: the shader's arithmetic is not the cost.
With hard's blur instants at most 2 px apart (``blur_step_px``; before: 1 px) every frame of the
bench's motion is one render (1.75 before): hard/easy 0.292-0.294 CPU, 0.297-0.298 wall,
against 0.267-0.274 and 0.251-0.254 for the 1 px spacing in alternating runs (load 23-34); one
hard render still costs 0.23-0.26 s CPU against about 0.07 s for a whole easy render.
``msaa`` (speed2, load 33, 4 rounds): without multisampling a hard render takes 0.48 of the CPU
(the 4 samples, not the shading, are half of llvmpipe's work), but the face's pixels move by 3.5
grey levels RMS, up to 99 at silhouettes, lips, teeth and dots (3.4 % of them by more than 3):
more than the sensor's own shot and read noise there (2.24), so ``hard`` keeps 4 samples. A
4-sample pass confined by the scissor to a box round the mouth still cost 0.84 of the full one
at 30 % of the area (its triangles are set up and binned all the same), so a 1-sample frame with
a multisampled mouth would cost more than today's.
``fragment_cost`` (speed15d, load 24-42): a hard render without shadows takes 0.61-0.70 of the CPU,
without textures 0.80-0.95; the shadow pass itself is about 0.04 (a 1024-texel map over the same
texels measured 0.97 and 1.02: not kept). So the key light's shadow look-ups (four gathers per
fragment) are a third of a hard render, and they are paid per fragment *invocation*: llvmpipe
shades whole blocks, and small triangles leave blocks partly covered, which is why the face's
triangle count costs as much as its pixels (a head with half the triangles, ``head_mesh`` 20, 2,
18, 32, took 0.74 of the CPU but moved both views' pixels by 1.06 grey levels RMS, the 99th percentile
by 4, before noise). A hard frame was 0.34-0.37 s of CPU, 0.25 s of it the render.
The light loops (frame22f, issue 22): pyrender's shader loops over its lights up to uniform counts,
which llvmpipe runs lane by lane with dynamically indexed light arrays; the one-pass renderer's
copy bounds them at compile time (:func:`lipgen.rig._onepass.fixed_light_shader`). The same bytes
(easy, default and hard frames of ``generate``), and one render costs 0.46 of the CPU on easy
and 0.52 on hard (0.225 -> 0.114 s; 6 interleaved rounds, load 9.8). So the lighting was much
of the fragment cost after all: with one light the loop still ran its dynamic form.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from lipgen.bench.compare import load_average
from lipgen.bench.preset_fidelity import measure as measure_fidelity

NAME = "presets"


def _contexts(tmp: Path, n: int) -> tuple[dict, object]:
    from lipgen.dataset import generate as gen
    from lipgen.dataset.settings import GenerateSettings
    from lipgen.dataset.simulation import simulate_motion

    hard = GenerateSettings.from_preset("hard", frames=n + 1, calib_frames=0)
    motion = simulate_motion(dataclasses.replace(hard, truth_physics="linear"))
    mesh_path = tmp / "mesh.npz"
    motion.mesh.save(mesh_path)
    workers = {}
    for name, s in (("easy", GenerateSettings.from_preset("easy", frames=n + 1, calib_frames=0)),
                    ("hard", hard)):
        out = tmp / name
        for sub in ("raw", "truth"):
            (out / sub).mkdir(parents=True, exist_ok=True)
        dots = None if name == "easy" else motion.dots.to_dict()
        ctx = gen._Context(str(out), s.to_dict(), np.asarray(motion.vertices), np.asarray(motion.poses),
                           np.asarray(motion.activations), str(mesh_path), dots)
        gen._WORKER.clear()
        gen._init_worker(ctx)
        gen._write(*gen._render_job(("frame", 0)))  # warm-up: shaders compiled, textures uploaded
        workers[name] = dict(gen._WORKER)
    gen._WORKER.clear()
    return workers, motion


def _shadow_filter(worker: dict, motion, reps: int) -> dict:
    """CPU of one shadowed render of the hard scene, lipgen's shadow filter over pyrender's: the
    hard worker's renderer with its shader cache swapped round by round (one GL context: pyrender
    ends the process's EGL display when any of its contexts is deleted)."""
    from pyrender.shader_program import ShaderProgramCache

    scenes = [worker["face"].scene(motion.vertices[i], motion.poses[i], lights=worker["lights"])
              for i in range(len(motion.vertices))]
    r = worker["renderer"]
    gl = r._renderer._renderer
    caches = {"lipgen": gl._program_cache, "pyrender": ShaderProgramCache()}
    cpu = {name: [] for name in caches}
    try:
        for k in range(reps + 1):
            for name, cache in caches.items():
                gl._program_cache = cache
                c0 = time.process_time()
                r.render_views(scenes[k % len(scenes)])
                if k:  # the first round compiles the shaders
                    cpu[name].append(time.process_time() - c0)
    finally:
        gl._program_cache = caches["lipgen"]
        caches["pyrender"].clear()
    ratio = np.asarray(cpu["lipgen"]) / np.maximum(cpu["pyrender"], 1e-9)
    return {"lipgen_over_pyrender_cpu": float(np.median(ratio)), "repeats": reps,
            "lipgen_filter_installed": type(caches["lipgen"]) is not ShaderProgramCache}


def _msaa(worker: dict, motion, reps: int) -> dict:
    """One hard render without multisampling (``RigRenderer.samples`` 0) against pyrender's 4
    samples, on the hard worker's renderer, interleaved: the CPU ratio (median per round) and how
    far the render's pixels move (both views, grey levels of the 8-bit render before the lens,
    sensor and codec) over the face's pixels (those more than 10 levels from the background)."""
    scenes = [worker["face"].scene(motion.vertices[i], motion.poses[i], lights=worker["lights"])
              for i in range(len(motion.vertices))]
    r = worker["renderer"]
    cpu, diffs, face_px = {0: [], 4: []}, [], 0
    try:
        for k in range(reps + 1):
            views = {}
            for samples in (4, 0):
                r.samples = samples
                r.render_views(scenes[k % len(scenes)])  # the framebuffer is made again for the new count
                c0 = time.process_time()
                views[samples] = [v[0].astype(np.int16) for v in r.render_views(scenes[k % len(scenes)])]
                if k:
                    cpu[samples].append(time.process_time() - c0)
            for a, b in zip(views[4], views[0], strict=True):
                face = np.abs(a - a[0, 0]).max(axis=-1) > 10  # the corner pixel is background
                diffs.append(np.abs(a - b).max(axis=-1)[face])
                face_px += int(face.sum())
    finally:
        r.samples = 4
    d = np.concatenate(diffs).astype(float)
    return {"no_msaa_over_msaa4_cpu": float(np.median(np.asarray(cpu[0]) / np.maximum(cpu[4], 1e-9))),
            "msaa4_cpu_s": float(np.median(cpu[4])), "face_rms": float(np.sqrt(np.mean(d**2))),
            "face_max": float(d.max()), "face_over_3": float(np.mean(d > 3)), "face_pixels": face_px,
            "repeats": reps}


def _split4(item):
    """``item`` with each triangle split in four at its edge midpoints (the same flat surface)."""
    F, n = item.faces, len(item.vertices)
    edges = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    unique, inv = np.unique(edges, axis=0, return_inverse=True)
    ab, bc, ca = (n + inv.reshape(3, -1)).copy()
    a, b, c = F.T

    def mid(x):
        return None if x is None else np.vstack([x, 0.5 * (x[unique[:, 0]] + x[unique[:, 1]])])

    faces = np.concatenate([np.stack(t, 1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
    fm = None if item.face_material is None else np.tile(item.face_material, 4)
    return dataclasses.replace(item, vertices=mid(item.vertices), faces=faces, normals=mid(item.normals),
                               face_material=fm, uv=mid(item.uv))


def _face_cost(worker: dict, motion, reps: int) -> dict:
    """CPU of one hard render in variants of its ``face`` item, over the whole render (interleaved)."""
    r = worker["renderer"]
    scene = worker["face"].scene(motion.vertices[1], motion.poses[1], lights=worker["lights"])

    def swap(make):
        items = tuple(make(it) if it.name == "face" else it for it in scene.items)
        return dataclasses.replace(scene, items=tuple(it for it in items if it is not None))

    variants = {"whole": scene, "no_face": swap(lambda it: None),
                "face_culled": swap(lambda it: dataclasses.replace(it, faces=it.faces[:, ::-1].copy())),
                "face_split4": swap(_split4)}
    cpu = {name: [] for name in variants}
    for k in range(reps + 1):
        for name, v in variants.items():
            r.render_views(v)  # uploads the variant's meshes
            c0 = time.process_time()
            r.render_views(v)
            if k:
                cpu[name].append(time.process_time() - c0)
    r.clear()
    whole = np.asarray(cpu["whole"])
    out = {f"{name}_over_whole_cpu": float(np.median(np.asarray(c) / whole)) for name, c in cpu.items()
           if name != "whole"}
    face = next(it for it in scene.items if it.name == "face")
    return out | {"whole_cpu_s": float(np.median(whole)), "face_triangles": len(face.faces),
                  "scene_triangles": int(sum(len(it.faces) for it in scene.items)), "repeats": reps}


def _fragment_cost(worker: dict, motion, reps: int) -> dict:
    """CPU of one hard render without its shadows (no shadow map drawn or read) and without its
    textures (the materials' plain colours), over the whole render, interleaved: what the
    per-fragment look-ups cost on llvmpipe."""
    r = worker["renderer"]
    scene = worker["face"].scene(motion.vertices[1], motion.poses[1], lights=worker["lights"])
    plain = dataclasses.replace(scene, items=tuple(
        dataclasses.replace(it, materials=type(it.materials)(dataclasses.replace(m, texture=None)
                                                              for m in it.materials))
        for it in scene.items))
    flags = r._flags

    def no_shadows():
        r._flags = r.pyrender.RenderFlags.NONE
        try:
            r.render_views(scene)
        finally:
            r._flags = flags

    variants = {"whole": lambda: r.render_views(scene), "no_shadows": no_shadows,
                "no_textures": lambda: r.render_views(plain)}
    cpu = {name: [] for name in variants}
    for k in range(reps + 1):
        for name, fn in variants.items():
            fn()  # uploads the variant's meshes
            c0 = time.process_time()
            fn()
            if k:
                cpu[name].append(time.process_time() - c0)
    r.clear()
    whole = np.asarray(cpu["whole"])
    return {f"{name}_over_whole_cpu": float(np.median(np.asarray(c) / whole)) for name, c in cpu.items()
            if name != "whole"} | {"whole_cpu_s": float(np.median(whole)), "repeats": reps}


def run(quick: bool = False) -> dict:
    from lipgen._threads import limit_worker_threads
    from lipgen.dataset import generate as gen
    from lipgen.rig import render

    n = 4 if quick else 16
    limit_worker_threads(1)  # as in every generate worker
    calls = [0]
    original = render.RigRenderer.render_views

    def counted(self, *args, **kwargs):
        calls[0] += 1
        return original(self, *args, **kwargs)

    load_before = load_average()
    cpu = {"easy": [], "hard": []}
    wall = {"easy": [], "hard": []}
    renders = 0
    with tempfile.TemporaryDirectory() as tmp:
        workers, motion = _contexts(Path(tmp), n)
        render.RigRenderer.render_views = counted
        try:
            for i in range(1, n + 1):
                for name in ("easy", "hard"):
                    gen._WORKER.clear()
                    gen._WORKER.update(workers[name])
                    k0 = calls[0]
                    c0, t0 = time.process_time(), time.perf_counter()
                    gen._write(*gen._render_job(("frame", i)))
                    cpu[name].append(time.process_time() - c0)
                    wall[name].append(time.perf_counter() - t0)
                    if name == "hard":
                        renders += calls[0] - k0
        finally:
            render.RigRenderer.render_views = original
            gen._WORKER.clear()
        shadow = _shadow_filter(workers["hard"], motion, 3 if quick else 8)
        face_cost = _face_cost(workers["hard"], motion, 3 if quick else 8)
        msaa = _msaa(workers["hard"], motion, 3 if quick else 8)
        fragment_cost = _fragment_cost(workers["hard"], motion, 3 if quick else 8)
        fidelity = measure_fidelity(workers["hard"], motion, range(1, 1 + (2 if quick else 6)))
        for w in workers.values():
            with contextlib.suppress(Exception):  # the first close ends the process's EGL display
                w["renderer"].close()
    ce, ch = np.asarray(cpu["easy"]), np.asarray(cpu["hard"])
    we, wh = np.asarray(wall["easy"]), np.asarray(wall["hard"])
    return {
        "frames": n,
        "size": "640x480",
        "hard_over_easy_fps": float(np.median(ce / ch)),
        "hard_over_easy_fps_wall": float(np.median(we / wh)),
        "cpu_per_frame_s": {"easy": float(np.median(ce)), "hard": float(np.median(ch))},
        "hard_renders_per_frame": renders / n,
        "shadow_filter": shadow,
        "face_cost": face_cost,
        "msaa": msaa,
        "fragment_cost": fragment_cost,
        "fidelity": fidelity,
        "target": {"hard_over_easy_fps": 0.5},
        "loadavg_before": load_before,
        "loadavg_after": load_average(),
        "cpu_count": os.cpu_count(),
    }
