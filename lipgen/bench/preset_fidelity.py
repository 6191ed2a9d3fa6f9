"""How far the ``hard`` preset's sampling choices move its frames, beside the sensor's noise.

Two settings decide how finely a ``hard`` frame is sampled: the motion-blur instants are at most
``blur_step_px`` apart (a mark's image moves at most that far between two rendered instants of
the exposure), and the head is tessellated by ``head_mesh``. Each is measured against a dense
reference on the preset's own frames, noise-free (lens, defocus, mirror,
exposure and the tone curve applied; no sensor noise, Bayer or JPEG):

- blur: the preset's instants against instants at most 0.25 px apart (at least 9), and the same
  for the 1 px spacing of the ``default`` preset;
- head: the preset's mesh and the ``default`` preset's mesh (:data:`~lipgen.subject.head.HEAD_MESH`)
  against one 1.5 times finer in every count, both at the frame time.

Figures: the RMS difference in grey levels over the face's pixels (those that differ from the
background by more than 10 grey levels), the RMS and largest shift of the ink dots' dark centroids
(9 x 9 px window round each visible dot's true projection), and beside them the sensor's noise on
the same pixels: shot and read noise alone, and with Bayer demosaicing and JPEG.
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["measure", "DENSE_STEP_PX", "FINE_HEAD"]

DENSE_STEP_PX = 0.25
"""Largest step of a mark's image between two instants of the dense exposure reference, px."""
FINE_HEAD = (42, 6, 54, 96)
"""The reference head tessellation: 1.5 times the default mesh's counts."""


def _dark_centroids(img: np.ndarray, uv: np.ndarray, half: int = 4) -> np.ndarray:
    """(k, 2) centroid of the darkness below the window's median round each ``uv`` (k, 2) (NaN at
    the border)."""
    g = img.mean(axis=-1)
    out = np.full((len(uv), 2), np.nan)
    yy, xx = np.mgrid[0:2 * half + 1, 0:2 * half + 1]
    for j, (u, v) in enumerate(uv):
        x0, y0 = int(round(u)) - half, int(round(v)) - half
        if x0 < 0 or y0 < 0 or x0 + 2 * half + 1 > g.shape[1] or y0 + 2 * half + 1 > g.shape[0]:
            continue
        win = g[y0:y0 + 2 * half + 1, x0:x0 + 2 * half + 1]
        wt = np.clip(np.median(win) - win, 0, None)
        if wt.sum() > 0:
            out[j] = x0 + (wt * xx).sum() / wt.sum(), y0 + (wt * yy).sum() / wt.sum()
    return out


def _dense_offsets(c, span: float) -> np.ndarray:
    m = max(9, int(1 + np.ceil(span / DENSE_STEP_PX)))
    return c.shutter * (np.arange(m) / (m - 1) - 0.5)


def measure(worker: dict, motion, frames) -> dict:
    """The figures of the module docstring on ``frames`` of ``motion`` for a ``hard`` worker
    (as :func:`lipgen.bench.preset_frames._contexts` sets it up).

    Parameters
    ----------
    worker : dict
        The hard preset's worker state (renderer, face, rig, former, lights, settings).
    motion : Motion
        Its simulated motion: ``vertices`` (F, n, 3), ``poses`` (F, 4, 4).
    frames : sequence of int
        Frame indices to measure.

    Returns
    -------
    dict
        ``blur`` and ``head`` (each: per variant ``face_rms``, ``dot_shift_rms_px``,
        ``dot_shift_max_px``; blur also ``renders_per_frame``), ``sensor_noise`` (``shot_read``,
        ``with_bayer_jpeg``: grey levels on the face's pixels), ``frames``.
    """
    from lipgen.dataset.film import exposure_offsets, sub_frame_states
    from lipgen.dataset.simulation import face_look, frame_truth
    from lipgen.rig.camera import VIEWS
    from lipgen.rig.imaging import FrameFormer
    from lipgen.subject.face import FaceModel
    from lipgen.subject.head import HEAD_MESH

    s, rig, r, face = worker["s"], worker["rig"], worker["renderer"], worker["face"]
    c, former, lights = s.conditions, worker["former"], worker["lights"]
    quiet_c = dataclasses.replace(c, full_well=0.0, read_noise=0.0, bayer=False, codec="png")
    quiet = FrameFormer(rig, quiet_c, former.exposure, former.wb)
    codec = FrameFormer(rig, dataclasses.replace(quiet_c, bayer=c.bayer, codec=c.codec), former.exposure,
                        former.wb)
    look = face_look(s)
    heads = {name: FaceModel(face.mesh, dataclasses.replace(look, head_mesh=mesh), dots=face.dots)
             for name, mesh in (("fine", FINE_HEAD), ("default_mesh", HEAD_MESH))}
    heads["preset"] = face

    def image(model, states):
        inst = []
        for V, P in states:
            views = r.render_views(model.scene(V, P, lights=lights))
            inst.append((views[0][0], views[1][0]))
        return rig.compose(*quiet.views(inst))

    keys = [("blur", "preset"), ("blur", "one_px"), ("head", "preset"), ("head", "default_mesh")]
    diffs = {k: [] for k in keys}
    shifts = {k: [] for k in diffs}
    renders = {"preset": [], "one_px": []}
    noise = {"shot_read": [], "with_bayer_jpeg": []}
    for i in frames:
        V, P = motion.vertices[i], motion.poses[i]
        ends = sub_frame_states(motion.vertices, motion.poses, i, c.sub_frame_offsets[[0, -1]])
        uv_ends = [rig.project(face.marks(Ve, Pe)[0])[0] for Ve, Pe in ends]
        span = float(np.nanmax(np.linalg.norm(uv_ends[1] - uv_ends[0], axis=-1), initial=0.0))
        t = frame_truth(rig, face, V, P, c.mirror_extent_mm)
        uv = np.vstack([rig.to_raw(view, t["uv"][v][t["visible"][v]]) for v, view in enumerate(VIEWS)])
        dense = sub_frame_states(motion.vertices, motion.poses, i, _dense_offsets(c, span))
        lin = {"dense": image(face, dense)}
        for name, step in (("preset", None), ("one_px", 1.0)):
            off = exposure_offsets(c, span, step)
            renders[name].append(len(off))
            lin[name] = image(face, sub_frame_states(motion.vertices, motion.poses, i, off))
        for name, model in heads.items():
            lin["head_" + name] = image(model, [(V, P)])
        grey = {k: quiet.sensor(x, None).astype(float) for k, x in lin.items()}
        ref = grey["dense"]
        mask = np.abs(ref - np.median(ref, axis=(0, 1))).max(axis=-1) > 10
        noisy = former.sensor(lin["preset"], np.random.default_rng([i, 1])).astype(float)
        noise["shot_read"].append((noisy - codec.sensor(lin["preset"], None))[mask])
        noise["with_bayer_jpeg"].append((noisy - grey["preset"])[mask])
        for (kind, name) in diffs:
            a, b = (grey[name], ref) if kind == "blur" else (grey["head_" + name], grey["head_fine"])
            diffs[(kind, name)].append((a - b)[mask])
            shift = _dark_centroids(a, uv) - _dark_centroids(b, uv)
            shifts[(kind, name)].append(np.linalg.norm(shift, axis=1))
    r.clear()

    def figures(key):
        d, sh = np.concatenate(diffs[key]).ravel(), np.concatenate(shifts[key])
        return {"face_rms": float(np.sqrt(np.mean(d**2))),
                "dot_shift_rms_px": float(np.sqrt(np.nanmean(sh**2))),
                "dot_shift_max_px": float(np.nanmax(sh))}

    out = {"frames": list(map(int, frames)),
           "blur": {name: figures(("blur", name)) | {"renders_per_frame": float(np.mean(renders[name]))}
                    for name in ("preset", "one_px")},
           "head": {name: figures(("head", name)) for name in ("preset", "default_mesh")},
           "sensor_noise": {k: float(np.std(np.concatenate(v).ravel())) for k, v in noise.items()}}
    out["blur"]["dense_step_px"] = DENSE_STEP_PX
    out["head"]["reference_mesh"] = list(FINE_HEAD)
    return out
