"""Writing a synthetic camera-mirror dataset (``lipgen generate``).

The subject (:mod:`lipgen.subject.motion`) is simulated once in the parent process; the frames are
then rendered and written by ``workers`` processes, each with its own OpenGL (EGL) context.
Every file is written atomically and depends only on the settings and its frame number (each
random choice is seeded from the dataset seed and the frame), so a run killed at any point
continues with ``resume=True`` where it stopped, and two runs with the same settings write
the same bytes.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import signal
import threading
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, ThreadPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lipgen import __version__
from lipgen._io import (
    atomic_write_bytes,
    atomic_write_json,
    png_bytes,
    save_npz,
)
from lipgen._threads import single_threaded
from lipgen.dataset.film import (
    exposure_offsets,
    film_frame,
    lighting_record,
    realize,
    rig_for,
    sub_frame_states,
)
from lipgen.dataset.folder import prepare_folder
from lipgen.dataset.layout import (
    CALIB_KIND,
    DEPTH_KIND,
    FRAME_KIND,
    SCHEMA,
    GenerateSettings,
    calib_paths,
    extra_paths,
    frame_paths,
    intact,
)
from lipgen.dataset.simulation import face_look, frame_truth, simulate_motion, speech_phones
from lipgen.rig.camera import VIEWS, MirrorRig, default_rig
from lipgen.rig.imaging import on_mirror
from lipgen.rig.noise import add_rounded_gaussian
from lipgen.rig.render import RenderedFrame
from lipgen.subject.face import FaceModel, look_record

__all__ = ["generate", "prepare_dataset", "render_jobs"]

log = logging.getLogger(__name__)

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


_WORKER: dict = {}


def _init_pool_worker(ctx: _Context, parent_pid: int) -> None:
    """A pool process: it ends when the generating process is killed; one BLAS thread (its
    siblings use the other cores); then it prepares to render."""
    from lipgen._lifeline import die_with_parent
    from lipgen._threads import limit_worker_threads

    die_with_parent(parent_pid)
    limit_worker_threads(1)
    _init_worker(ctx)


def _init_worker(ctx: _Context, renderer=None) -> None:
    from lipgen.mesh.lipmesh import LipMesh
    from lipgen.rig.backends import open_renderer
    from lipgen.rig.target import Chessboard

    s = GenerateSettings.from_dict(ctx.settings)
    c = s.conditions
    rig = rig_for(s.size, c, default_rig)
    mesh = LipMesh.load(ctx.mesh_path)
    dots = None
    if ctx.dots is not None:
        from lipgen.subject.inkdots import SurfaceDots

        dots = SurfaceDots.from_dict(ctx.dots, mesh.n_faces)
    face = FaceModel(mesh, face_look(s), dots=dots)
    _WORKER.update(ctx=ctx, s=s, rig=rig, mesh=mesh, face=face, board=Chessboard(*s.board),
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

        board, P, lens = _calib_poses(rig, w["board"], s)[i]
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
    """The optional depth and mask files of a frame, as ``(path, writer)`` pairs."""
    out = []
    if rendered.depth is not None:
        z = np.where(rendered.depth > 0, rendered.depth, np.nan).astype(np.float32)  # 0: nothing drawn
        out.append((depth_path, lambda p: save_npz(p, DEPTH_KIND, SCHEMA, {"depth": z})))
    if rendered.labels is not None:
        mask = png_bytes(rendered.labels.astype(np.uint8), level)
        out.append((mask_path, lambda p: atomic_write_bytes(p, mask)))
    return out


def _write(image, truth, png, npz, kind_tag, level, extras=()) -> None:
    """Write a frame's depth and mask (if asked), its PNG, then its truth, each atomically; the frame
    counts as written once the truth exists, so the truth goes last."""
    for path, write in extras:
        write(path)
    atomic_write_bytes(png, png_bytes(image, level))
    save_npz(npz, kind_tag, SCHEMA, truth)


def _frame_intact(out: Path, i: int, s: GenerateSettings) -> bool:
    files = list(zip(frame_paths(out, i), (None, FRAME_KIND), strict=True))
    depth, mask = extra_paths(out, i)
    files += ([(depth, DEPTH_KIND)] if s.depth else []) + ([(mask, None)] if s.masks else [])
    return all(intact(p, k) for p, k in files)


def _calib_poses(rig: MirrorRig, board, s: GenerateSettings) -> list:
    """Per calibration frame: (board, pose, view a lens frame fills or None)."""
    from lipgen.rig.target import calibration_targets

    key = ("calib_poses", s.calib_frames, s.lens_frames)
    if key not in _WORKER:
        rng = np.random.default_rng([s.seed, _CALIB_STREAM])
        _WORKER[key] = calibration_targets(rig, board, s.calib_frames - s.lens_frames, s.lens_frames, rng,
                                           s.conditions.mirror_extent_mm)
    return _WORKER[key]


def _write_speech(out: Path, phones, audio) -> None:
    """``speech/phones.json`` (phones with start and end in s, how they were found) and, from a
    recording, ``speech/audio.wav`` (the 16 kHz mono audio they were found in)."""
    from lipgen.speech.audio import write_wav

    (out / "speech").mkdir(exist_ok=True)
    atomic_write_json(out / "speech" / "phones.json", {
        "phones": list(phones.labels), "start_s": phones.start.tolist(), "end_s": phones.end.tolist(),
        "source": phones.source, "confidence": phones.confidence})
    if audio is not None:
        write_wav(out / "speech" / "audio.wav", audio)


def prepare_dataset(out, s: GenerateSettings, resume: bool = False) -> tuple[_Context, list[tuple[str, int]]]:
    """Simulate the subject, check the rig sees it, and lay out the dataset folder ``out``
    (manifest, mesh, sub-folders); nothing is rendered yet.

    Returns the context every renderer needs and the jobs still to do: ``("calib", i)`` and
    ``("frame", i)`` whose files are not all written. Rendering the jobs in any order, split in any
    way between processes or machines (:func:`render_jobs`), writes the same bytes.
    """
    from lipgen.dataset.layout import build_manifest
    from lipgen.mesh.lipmesh import LipMesh
    from lipgen.rig.backends import check_renderer

    out = Path(out)
    check_renderer(s.renderer)  # e.g. cycles without bpy: say so before anything is simulated or written
    rig = rig_for(s.size, s.conditions, default_rig)
    phones, audio = speech_phones(s) if (s.speech or s.speech_text) else (None, None)
    motion = simulate_motion(s, phones)
    marks = np.concatenate([motion.markers_world, motion.nose_world[:, None]], axis=1)
    rig.check_sees(marks.reshape(-1, 3), margin=2.0, what="subject's marks over the motion")
    mesh: LipMesh = motion.mesh
    dots = None if motion.dots is None else motion.dots.to_dict()
    subject = None
    if s.subject_seed is not None:
        from lipgen.subject.shape import sample_shape

        subject = {"subject_seed": s.subject_seed, "shape": sample_shape(s.subject_seed).to_dict(),
                   "shape_units": "mm (lipgen.subject.shape.SHAPE_RANGES)", "dots": dots,
                   "truth_physics": s.truth_physics}
    if s.preset is not None:
        from lipgen.dataset.presets import get_preset

        subject = (subject or {}) | {"preset": get_preset(s.preset).to_dict()}
    if s.motion_sources == "independent":
        from lipgen.subject import independent as ind

        record = {"sources": list(ind.INDEPENDENT_SOURCES), "jaw_gain": ind.JAW_GAIN,
                  "residual_rms_mm": ind.RESIDUAL_MM}
        subject = (subject or {}) | {"motion": record}
    manifest = build_manifest(s, rig, mesh, list(motion.actions), __version__, subject)
    if not s.conditions.is_ideal:
        manifest["lighting"] = lighting_record(realize(s.conditions, s.seed))
        manifest["scene"] = look_record(face_look(s), len(mesh.markers) + 1)
    if s.conditions.video_codec:
        from lipgen.dataset.video import check_video_codec

        check_video_codec(s.conditions.video_codec)  # before anything is written
        manifest["video"] = {"file": VIDEO_FILE, "codec": s.conditions.video_codec, "fps": s.fps,
                             "crf": s.conditions.video_crf, "frames": s.frames,
                             "content": "the raw frames in order, H.264 (yuv420p)"}
    if s.calib_frames:  # can the board be placed at all? (a tiny --size cannot): fail before any write
        from lipgen.rig.target import Chessboard, calibration_targets

        rng = np.random.default_rng([s.seed, _CALIB_STREAM])
        calibration_targets(rig, Chessboard(*s.board), s.calib_frames - s.lens_frames, s.lens_frames, rng,
                            s.conditions.mirror_extent_mm)
    if not prepare_folder(out, manifest, resume):
        atomic_write_json(out / "manifest.json", manifest)  # first, so the folder is known as ours
    for sub in ("raw", "truth", "calib") + (("depth",) if s.depth else ()) + (("masks",) if s.masks else ()):
        (out / sub).mkdir(exist_ok=True)
    mesh_path = out / "mesh.npz"
    if not intact(mesh_path, "lipgen.LipMesh"):
        mesh.save(mesh_path)
    if phones is not None:
        _write_speech(out, phones, audio)
    # a resume checks every file it keeps (a cheap decode): empty or truncated ones are redone
    jobs = [("calib", i) for i in range(s.calib_frames)
            if not all(intact(p, k) for p, k in zip(calib_paths(out, i), (None, CALIB_KIND), strict=True))]
    jobs += [("frame", i) for i in range(s.frames) if not _frame_intact(out, i, s)]
    done = s.calib_frames + s.frames - len(jobs)
    if done:
        log.info("resuming %s: %d files already written, %d to go", out, done, len(jobs))
    ctx = _Context(str(out), s.to_dict(), np.asarray(motion.vertices), np.asarray(motion.poses),
                   np.asarray(motion.activations), str(mesh_path), dots)
    return ctx, jobs


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


@contextlib.contextmanager
def _deferred_sigint():
    """Ctrl-C sets a flag (the yielded list) instead of raising wherever the main thread is.

    A KeyboardInterrupt raised inside ``concurrent.futures.wait`` can leave some futures' locks
    held (it takes them all on entry), and the pool's manager thread, blocked on one, never lets
    the pool shut down: generate then hung instead of ending. The loop raises at a safe point.
    """
    flag: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return
    old = signal.signal(signal.SIGINT, lambda signum, frame: flag.append(signum))
    try:
        yield flag
    finally:
        signal.signal(signal.SIGINT, old)


def generate(out, settings: GenerateSettings | None = None, workers: int = 1, resume: bool = False,
             progress: bool = True) -> Path:
    """Write a dataset to folder ``out`` (layout: :mod:`lipgen.dataset`).

    Parameters
    ----------
    out : path
        New or empty folder; or, with ``resume``, a dataset made with the same settings.
    settings : GenerateSettings, optional
        Defaults to ``GenerateSettings()``.
    workers : int
        Local processes rendering frames (each opens its own EGL context).
    resume : bool
        Continue an interrupted dataset: frames already written are kept, not redone.
    progress : bool
        Show a tqdm progress bar.

    Raises
    ------
    DatasetError
        ``out`` is another dataset, not a dataset, differs in settings, or is not writable.
    ValueError
        Bad settings (unknown viseme in the script, a rig that does not see the face, ...).
    """
    from tqdm import tqdm

    if isinstance(workers, bool) or int(workers) != workers or not 1 <= workers <= 64:
        raise ValueError(f"workers must be a whole number in [1, 64], got {workers!r}")
    s = GenerateSettings() if settings is None else settings
    out = Path(out)
    ctx, jobs = prepare_dataset(out, s, resume)
    done = s.calib_frames + s.frames - len(jobs)
    bar = tqdm(total=s.calib_frames + s.frames, initial=done, desc="lipgen generate", unit="frame",
               disable=not progress)
    try:
        if workers == 1 or len(jobs) <= 1:
            _init_worker(ctx)
            # encode and write frame k in a thread while frame k + 1 renders (PNG/zlib release the GIL)
            writer = ThreadPoolExecutor(1)
            try:
                pending = None
                for job in jobs:
                    result = _render_job(job)
                    if pending is not None:
                        pending.result()
                        bar.update()
                    pending = writer.submit(_write, *result)
                if pending is not None:
                    pending.result()
                    bar.update()
            finally:
                writer.shutdown(wait=True)
                _WORKER.pop("renderer").close()
                _WORKER.clear()
        else:
            spawn = multiprocessing.get_context("spawn")  # a fresh process per GL context
            pool = ProcessPoolExecutor(workers, mp_context=spawn, initializer=_init_pool_worker,
                                       initargs=(ctx, os.getpid()))
            with pool as ex, _deferred_sigint() as interrupted:
                futures = [ex.submit(_run_job, job) for job in jobs]
                pending = set(futures)
                try:
                    while pending:
                        if interrupted:
                            raise KeyboardInterrupt
                        finished, pending = wait(pending, timeout=0.25, return_when=FIRST_COMPLETED)
                        for fut in finished:
                            fut.result()  # re-raise a worker's error here
                            bar.update()
                except BaseException:
                    for fut in pending:
                        fut.cancel()
                    raise
    finally:
        bar.close()
    if s.conditions.video_codec and not (out / VIDEO_FILE).is_file():
        _write_video(out, s)
    return out


VIDEO_FILE = "video.mp4"


def _write_video(out: Path, s: GenerateSettings) -> None:
    """Encode the written raw frames, in order, as the dataset's video (atomically)."""
    from PIL import Image

    from lipgen.dataset.video import write_video

    def frames():
        for i in range(s.frames):
            with Image.open(frame_paths(out, i)[0]) as im:
                yield np.asarray(im.convert("RGB"))

    log.info("encoding %d frames as %s video", s.frames, s.conditions.video_codec)
    write_video(out / VIDEO_FILE, frames(), s.fps, s.conditions.video_codec, s.conditions.video_crf)

