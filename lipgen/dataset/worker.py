"""A ``lipgen generate`` worker: its state, and rendering and writing one frame.

A worker (the generating process itself, or one of its pool's processes) holds a renderer, the
subject's face and the rig (:func:`_init_worker`); :func:`_render_job` makes one frame's image and
truth (or one calibration frame's) and :func:`_write` writes them. Every random choice is seeded
from the dataset seed and the frame, so a frame's bytes depend only on the settings and its
number, whichever worker renders it and in whatever order (:func:`render_jobs`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lipgen._io import atomic_write_bytes, png_bytes, save_npz
from lipgen._threads import single_threaded
from lipgen.dataset.film import exposure_offsets, film_frame, realize, rig_for, sub_frame_states
from lipgen.dataset.layout import (
    CALIB_KIND,
    DEPTH_KIND,
    FRAME_KIND,
    SCHEMA,
    GenerateSettings,
    calib_paths,
    extra_paths,
    frame_paths,
)
from lipgen.dataset.simulation import face_look, frame_truth
from lipgen.rig.camera import VIEWS, MirrorRig, default_rig
from lipgen.rig.imaging import on_mirror
from lipgen.rig.noise import add_rounded_gaussian
from lipgen.rig.render import RenderedFrame
from lipgen.subject.face import FaceModel

__all__ = ["render_jobs"]

_NOISE_STREAM, _CALIB_STREAM = 3, 4


def _age(i: int, s: GenerateSettings) -> float:
    """How far through the clip frame ``i`` is (0 first, 1 last)."""
    return i / max(s.frames - 1, 1)


@dataclass
class _Context:
    """What a worker needs to render and write any frame."""

    out: str
    settings: dict
    vertices: np.ndarray
    poses: np.ndarray
    activations: np.ndarray
    mesh_path: str
    dots: dict | None = None
    calib_targets: list | None = None
    """The calibration frames' boards (:func:`lipgen.rig.target.calibration_targets`), drawn once
    by ``prepare_dataset`` (a second of rejection sampling with lens frames); None: each worker
    draws them again (the same seed gives the same boards)."""


_WORKER: dict = {}


def _init_pool_worker(ctx: _Context, parent_pid: int) -> None:
    """A pool process: it ends when the generating process is killed; one BLAS thread (its
    siblings use the other cores); freed memory kept for reuse; then it prepares to render."""
    from lipgen._lifeline import die_with_parent
    from lipgen._memory import keep_freed_memory
    from lipgen._threads import limit_worker_threads

    die_with_parent(parent_pid)
    limit_worker_threads(1)
    keep_freed_memory()  # each frame's large arrays reuse the last frame's memory (lipgen._memory)
    _init_worker(ctx)
    _WORKER["clean"] = False  # generate's own pool: the folder was cleaned when prepared


def _init_worker(ctx: _Context, renderer=None) -> None:
    from lipgen.mesh.lipmesh import LipMesh
    from lipgen.rig.backends import open_renderer

    s = GenerateSettings.from_dict(ctx.settings)
    c = s.conditions
    rig = rig_for(s.size, c, default_rig)
    mesh = LipMesh.load(ctx.mesh_path)
    dots = None
    if ctx.dots is not None:
        from lipgen.subject.inkdots import SurfaceDots

        dots = SurfaceDots.from_dict(ctx.dots, mesh.n_faces)
    face = FaceModel(mesh, face_look(s), dots=dots)
    _WORKER.update(ctx=ctx, s=s, rig=rig, mesh=mesh, face=face,
                   renderer=renderer or open_renderer(s.renderer, rig, c, s.cycles_samples, s.seed % 2**31))
    if not c.is_ideal:
        from lipgen.rig.imaging import FrameFormer

        light = realize(c, s.seed)
        _WORKER.update(lights=light["lights"], former=FrameFormer(rig, c, light["exposure"],
                                                                   light["white_balance"]))


def _noisy(image: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """``clip(round(image + sigma * z), 0, 255)``, drawn as integers (:mod:`lipgen.rig.noise`)."""
    return add_rounded_gaussian(image, sigma, rng)


def _run_job(job: tuple[str, int]) -> tuple[str, int]:
    """Render and write one frame (or calibration frame)."""
    _write(*_render_job(job))
    return job


@single_threaded  # many small numpy calls (truth, visibility): 2 BLAS threads only wait under load
def _render_job(job: tuple[str, int]):
    """The image, truth and destination of one job (nothing written yet)."""
    w = _WORKER
    ctx, s, rig = w["ctx"], w["s"], w["rig"]
    kind, i = job
    out = Path(ctx.out)
    rng = np.random.default_rng([s.seed, _NOISE_STREAM, 0 if kind == "frame" else 1, i])
    c = s.conditions
    if kind == "frame":
        V, P = ctx.vertices[i], ctx.poses[i]
        if c.is_ideal:
            rendered = w["renderer"].render(w["face"].scene(V, P, age=_age(i, s)), depth=s.depth,
                                            labels=s.masks)
        else:
            ends = sub_frame_states(ctx.vertices, ctx.poses, i, c.sub_frame_offsets[[0, -1]])
            uv_ends = [rig.project(w["face"].marks(Vs, Ps)[0])[0] for Vs, Ps in ends]
            span = np.nanmax(np.linalg.norm(uv_ends[1] - uv_ends[0], axis=-1), initial=0.0)
            offsets = exposure_offsets(c, float(span))
            states = sub_frame_states(ctx.vertices, ctx.poses, i, offsets)
            rendered = RenderedFrame(*film_frame(w["renderer"], w["former"], w["face"], states, w["lights"],
                                                 rng, s.depth, s.masks, age=_age(i, s)))
        image = _noisy(rendered.image, s.noise, rng)
        extras = _extras(rendered, *extra_paths(out, i), s.png_compress_level)
        truth = frame_truth(rig, w["face"], V, P, c.mirror_extent_mm)
        if c.shutter > 0:  # where the marks were while the shutter was open (start, end)
            truth["uv_exposure"] = np.stack(uv_ends)
        names = np.array(list(w["mesh"].marker_names) + ["nose"])
        truth.update(index=np.int64(i), time=np.float64(i / s.fps), vertices=V, pose=P,
                     activations=ctx.activations[i], mark_names=names, views=np.array(VIEWS),
                     marks_model=w["face"].marks(V)[0])  # identity pose: the model frame
        png, npz, kind_tag = *frame_paths(out, i), FRAME_KIND
    else:
        from lipgen.rig.target import board_scene

        board, P, lens = _calib_poses(ctx, rig, s)[i]
        if c.is_ideal:
            image = w["renderer"].render(board_scene(board, P)).image
        else:
            views = w["renderer"].render_views(board_scene(board, P))
            image = w["former"].form([(views[0][0], views[1][0])], rng)
        image = _noisy(image, s.noise, rng)
        obj = board.object_points()
        Xw = obj @ P[:3, :3].T + P[:3, 3]
        uv, _, inside = rig.project(Xw)
        inside[0] &= on_mirror(rig, c.mirror_extent_mm, Xw)
        truth = {"index": np.int64(i), "A": P[:3, :3], "b": P[:3, 3], "pose": P, "corners_board": obj,
                 "corners_world": Xw, "uv": uv, "in_image": inside, "views": np.array(VIEWS),
                 "uv_raw": np.stack([rig.to_raw(view, uv[v]) for v, view in enumerate(VIEWS)])}
        if lens:  # a lens frame: the board it shows, and the view it fills
            truth.update(lens_view=np.array(lens),
                         board=np.array([board.inner_cols, board.inner_rows, board.square], float))
        png, npz, kind_tag = *calib_paths(out, i), CALIB_KIND
        extras = []
    return image, truth, png, npz, kind_tag, s.png_compress_level, extras


def _extras(rendered, depth_path: Path, mask_path: Path, level: int) -> list:
    """The optional depth and mask files of a frame, as ``(path, writer(path, clean))`` pairs."""
    out = []
    if rendered.depth is not None:
        z = np.where(rendered.depth > 0, rendered.depth, np.nan).astype(np.float32)  # 0: nothing drawn
        out.append((depth_path, lambda p, clean: save_npz(p, DEPTH_KIND, SCHEMA, {"depth": z}, clean=clean)))
    if rendered.labels is not None:
        mask = png_bytes(rendered.labels.astype(np.uint8), level)
        out.append((mask_path, lambda p, clean: atomic_write_bytes(p, mask, clean=clean)))
    return out


def _write(image, truth, png, npz, kind_tag, level, extras=()) -> None:
    """Write a frame's depth and mask (if asked), its PNG, then its truth, each atomically; the frame
    counts as written once the truth exists, so the truth goes last.

    Within ``generate`` (``_WORKER["clean"]`` False) no write scans its folder for a killed run's
    temporary files: the folder's preparation has just removed them
    (:func:`lipgen.dataset.folder.prepare_folder`), and a scan per file grows with the folder (about
    2 ms per file at 3000 frames). :func:`render_jobs` (campaign chunks, perhaps a retry of a killed
    worker's chunk without a new preparation) keeps the scan of each file's own leftovers."""
    clean = _WORKER.get("clean", True)
    for path, write in extras:
        write(path, clean)
    atomic_write_bytes(png, png_bytes(image, level), clean=clean)
    save_npz(npz, kind_tag, SCHEMA, truth, clean=clean)


def draw_calib_boards(rig: MirrorRig, s: GenerateSettings) -> list:
    """Per calibration frame of settings ``s``: (board, pose, view a lens frame fills or None), drawn
    from the dataset seed's calibration stream (:func:`lipgen.rig.target.calibration_targets`)."""
    from lipgen.rig.target import Chessboard, calibration_targets

    rng = np.random.default_rng([s.seed, _CALIB_STREAM])
    return calibration_targets(rig, Chessboard(*s.board), s.calib_frames - s.lens_frames, s.lens_frames, rng,
                               s.conditions.mirror_extent_mm)


def _calib_poses(ctx: _Context, rig: MirrorRig, s: GenerateSettings) -> list:
    """The context's boards (drawn by ``prepare_dataset``), else drawn once in this worker."""
    if ctx.calib_targets is not None:
        return ctx.calib_targets
    key = ("calib_poses", s.calib_frames, s.lens_frames)
    if key not in _WORKER:
        _WORKER[key] = draw_calib_boards(rig, s)
    return _WORKER[key]


def render_jobs(ctx: _Context, jobs) -> int:
    """Render and write ``jobs`` (from :func:`prepare_dataset`) in this process; returns how many.

    The renderer is kept for the next call with the same context (a worker that renders many
    chunks of one dataset opens one GL context), and for another dataset of the same size and
    image conditions, cleared (making one costs about 3 frames' rendering).
    """
    if _WORKER.get("key") != (ctx.out, ctx.mesh_path):
        rig_key = (tuple(ctx.settings["size"]), repr(ctx.settings.get("conditions")),
                   ctx.settings.get("renderer", "pyrender"))
        keep = _WORKER.pop("renderer", None) if _WORKER.get("rig_key") == rig_key else None
        if keep is not None and not hasattr(keep, "clear"):  # Cycles: a new scene per dataset
            keep.close()
            keep = None
        if keep is not None:
            keep.clear()
        _close_worker()
        _init_worker(ctx, keep)
        _WORKER.update(key=(ctx.out, ctx.mesh_path), rig_key=rig_key)
    _WORKER["ctx"] = ctx
    n = 0
    for job in jobs:
        _write(*_render_job(tuple(job)))
        n += 1
    return n


def _close_worker() -> None:
    renderer = _WORKER.pop("renderer", None)
    if renderer is not None:
        renderer.close()
    _WORKER.clear()
