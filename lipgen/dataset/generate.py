"""Writing a synthetic camera-mirror dataset (``lipgen generate``).

The subject (:mod:`lipgen.subject.motion`) is simulated once in the parent process; the frames are
then rendered and written by ``workers`` processes, each with its own OpenGL (EGL) context
(:mod:`lipgen.dataset.worker`). Every file is written atomically and depends only on the settings
and its frame number (each random choice is seeded from the dataset seed and the frame), so a run
killed at any point continues with ``resume=True`` where it stopped, and two runs with the same
settings write the same bytes.
"""

from __future__ import annotations

import contextlib
import json
import logging
import multiprocessing
import os
import signal
import threading
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, ThreadPoolExecutor, wait
from pathlib import Path

import numpy as np

from lipgen import __version__
from lipgen._io import atomic_write_json
from lipgen._memory import reuse_freed_memory
from lipgen._validate import check_workers
from lipgen.dataset.film import lighting_record, realize, rig_for
from lipgen.dataset.folder import check_folder, check_same_dataset, prepare_folder
from lipgen.dataset.footprint import check_motion_memory
from lipgen.dataset.layout import (
    CALIB_KIND,
    DEPTH_KIND,
    FRAME_KIND,
    GenerateSettings,
    calib_paths,
    extra_paths,
    frame_paths,
    intact,
)
from lipgen.dataset.simulation import face_look, simulate_motion, speech_phones
from lipgen.dataset.worker import (  # noqa: F401  (the private names: bench and tests drive a worker)
    _WORKER,
    _close_worker,
    _Context,
    _init_pool_worker,
    _init_worker,
    _render_job,
    _run_job,
    _write,
    draw_calib_boards,
    render_jobs,
)
from lipgen.rig.camera import default_rig
from lipgen.subject.face import look_record

__all__ = ["generate", "prepare_dataset", "render_jobs"]

log = logging.getLogger(__name__)


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


def _frame_intact(out: Path, i: int, s: GenerateSettings) -> bool:
    files = list(zip(frame_paths(out, i), (None, FRAME_KIND), strict=True))
    depth, mask = extra_paths(out, i)
    files += ([(depth, DEPTH_KIND)] if s.depth else []) + ([(mask, None)] if s.masks else [])
    return all(intact(p, k) for p, k in files)


def prepare_dataset(out, s: GenerateSettings, resume: bool = False, progress: bool = False,
                    workers: int = 1) -> tuple[_Context, list[tuple[str, int]]]:
    """Simulate the subject, check the rig sees it, and lay out the dataset folder ``out``
    (manifest, mesh, sub-folders); nothing is rendered yet.

    Returns the context every renderer needs and the jobs still to do: ``("calib", i)`` and
    ``("frame", i)`` whose files are not all written. Rendering the jobs in any order, split in any
    way between processes or machines (:func:`render_jobs`), writes the same bytes.
    """
    from lipgen.dataset.layout import build_manifest
    from lipgen.dataset.manifest import settings_entries
    from lipgen.mesh.lipmesh import LipMesh
    from lipgen.rig.backends import check_renderer

    out = Path(out)
    check_renderer(s.renderer)  # e.g. cycles without bpy: say so before anything is simulated or written
    old = check_folder(out, resume)  # another dataset, a foreign folder: refused before the truth physics
    rig = rig_for(s.size, s.conditions, default_rig)
    if old is not None:  # --resume with other settings: refused now too, not after the physics
        check_same_dataset(out, old, json.loads(json.dumps(settings_entries(s, rig))))
    # before the physics, not killed after it
    check_motion_memory(s.frames, s.subject_resolution, s.truth_physics, workers)
    if s.conditions.video_codec:
        from lipgen.dataset.video import check_video_codec

        check_video_codec(s.conditions.video_codec)  # the encoder: before the truth physics and any write
    # can the board be placed at all? (a tiny --size cannot): before the truth physics
    targets = draw_calib_boards(rig, s) if s.calib_frames else None
    phones, audio = speech_phones(s) if (s.speech or s.speech_text) else (None, None)
    motion = simulate_motion(s, phones, progress=progress)  # the truth physics' bar
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
        manifest["video"] = {"file": VIDEO_FILE, "codec": s.conditions.video_codec, "fps": s.fps,
                             "crf": s.conditions.video_crf, "frames": s.frames,
                             "content": "the raw frames in order, H.264 (yuv420p)"}
    # checked again, not reused from check_folder: another run may have written here during the physics
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
                   np.asarray(motion.activations), str(mesh_path), dots, targets)
    return ctx, jobs


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
        ``out`` is another dataset, not a dataset, differs in settings, or is not writable; or the
        truth motion would not fit in the free memory (:mod:`lipgen.dataset.footprint`).
    ValueError
        Bad settings (unknown viseme in the script, a rig that does not see the face, ...).
    """
    workers = check_workers(workers)
    s = GenerateSettings() if settings is None else settings
    with reuse_freed_memory():  # each frame's large arrays reuse the last frame's memory: no page faults
        return _generate(Path(out), s, workers, resume, progress)


def _generate(out: Path, s: GenerateSettings, workers: int, resume: bool, progress: bool) -> Path:
    from tqdm import tqdm

    ctx, jobs = prepare_dataset(out, s, resume, progress=progress, workers=workers)
    done = s.calib_frames + s.frames - len(jobs)
    bar = tqdm(total=s.calib_frames + s.frames, initial=done, desc="lipgen generate", unit="frame",
               disable=not progress)
    try:
        if workers == 1 or len(jobs) <= 1:
            _init_worker(ctx)
            _WORKER["clean"] = False  # prepare_dataset has just removed a killed run's temporaries
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
