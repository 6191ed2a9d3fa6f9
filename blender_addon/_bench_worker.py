"""Timing of the add-on inside Blender, for the ``blender`` suite of ``lipgen bench``.

Not part of the extension (excluded in the manifest's build patterns). The suite runs it in its
own process, ``python -m blender_addon._bench_worker OUT.json [--quick]`` from the source tree,
so bpy never enters the benchmarking process. Figures are seconds, with a baseline measured in
the same process: the same depsgraph evaluation of the mesh without any shape key.
"""

from __future__ import annotations

import json
import sys
import time

import bpy
import numpy as np

from lipgen.blender import clear_physics_cache

from . import bridge, register


def _best_median(fn, repeat: int) -> dict:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return {"best_s": float(np.min(times)), "median_s": float(np.median(times)), "repeat": repeat}


def _evaluate(obj) -> None:
    dg = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(dg)
    me = ev.to_mesh()
    co = np.empty(3 * len(me.vertices), np.float32)
    me.vertices.foreach_get("co", co)
    ev.to_mesh_clear()


def playback(resolution: int, n_modes: int, n_frames: int) -> dict:
    """Per-frame time of frame_set + depsgraph evaluation + to_mesh for a keyframed mode rig."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.object.lipgen_add_lips(resolution=resolution)
    obj = bpy.context.active_object
    plain = bpy.data.objects.new("plain", obj.data.copy())  # same mesh, no shape keys
    bpy.context.collection.objects.link(plain)
    plain.shape_key_clear()
    t0 = time.perf_counter()
    bpy.ops.object.lipgen_build_modes(n_modes=n_modes)
    build_s = time.perf_counter() - t0
    rng = np.random.default_rng(0)
    frames = np.arange(1, n_frames + 1)
    for i in range(n_modes):
        fc = bridge.fcurve_ensure(obj, f"lipgen.modes[{i}].value")
        bridge.set_keyframes(fc, frames[::5], rng.uniform(-2, 2, len(frames[::5])))
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, n_frames

    def rig():
        for f in frames:
            scene.frame_set(int(f))
            _evaluate(obj)

    def bare():
        for f in frames:
            scene.frame_set(int(f))
            _evaluate(plain)

    rig_t = _best_median(rig, 3)
    bare_t = _best_median(bare, 3)
    per = {k: rig_t[k] / n_frames for k in ("best_s", "median_s")}
    base = {k: bare_t[k] / n_frames for k in ("best_s", "median_s")}
    return {"n_vertices": len(obj.data.vertices), "n_modes": n_modes, "n_frames": n_frames,
            "build_modes_s": build_s, "per_frame_s": per, "baseline_no_keys_per_frame_s": base,
            "ratio_to_baseline": per["median_s"] / base["median_s"]}


def preview(resolution: int, repeat: int) -> dict:
    """Time of one live-preview update (the magnitude slider's update callback) and of the
    depsgraph evaluation that shows it."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.object.lipgen_add_lips(resolution=resolution)
    obj = bpy.context.active_object
    s = obj.lipgen
    lips = np.flatnonzero(np.linalg.norm(bridge.mesh_vertices(obj.data)[:, :2], axis=1) < 6.0)
    bridge.set_vertex_group(obj, "LipGen Force", lips[: max(3, len(lips) // 20)])
    s.force_group = "LipGen Force"
    clear_physics_cache()  # time the factorisation, not a cache hit from the playback run
    t0 = time.perf_counter()
    bpy.ops.object.lipgen_build_physics()
    physics_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    s.force_preview = True  # reads the group, solves the four unit responses
    first_s = time.perf_counter() - t0
    assert "LipGen Preview" in obj.data.shape_keys.key_blocks, s.force_status
    values = iter(np.linspace(0.1, 3.0, 10 * repeat))

    def update():
        s.force_magnitude = float(next(values))

    def update_and_show():
        s.force_magnitude = float(next(values))
        _evaluate(obj)

    def write_only():  # baseline: writing the same shape key from a ready array
        kb = obj.data.shape_keys.key_blocks["LipGen Preview"]
        bridge.set_shape_key_co(kb, co)
        obj.data.update()

    co = bridge.mesh_vertices(obj.data)
    upd = _best_median(update, repeat)
    shown = _best_median(update_and_show, repeat)
    base = _best_median(write_only, repeat)
    return {"n_vertices": len(obj.data.vertices), "force_vertices": int(max(3, len(lips) // 20)),
            "factorise_s": physics_s, "first_preview_s": first_s, "update_s": upd,
            "update_and_evaluate_s": shown, "baseline_write_key_s": base,
            "ratio_update_to_write": upd["median_s"] / base["median_s"],
            "target_s": 0.030, "meets_target": upd["median_s"] < 0.030}


def main(out: str, quick: bool) -> None:
    register()
    fine = 2 if quick else 3  # resolution 3 has 11,352 vertices
    result = {
        "playback_res0": playback(0, 10, 20 if quick else 120),
        f"playback_res{fine}": playback(fine, 10, 10 if quick else 60),
        f"preview_res{fine}": preview(fine, 5 if quick else 20),
    }
    with open(out, "w") as fh:
        json.dump(result, fh, indent=2)


if __name__ == "__main__":
    main(sys.argv[1], "--quick" in sys.argv)
