"""Bench suite ``tracking``: what ``lipgen reconstruct``'s tracking costs per frame, with the
forward-backward cross-check (the default since xc27) and without it, against OpenCV's blob detector.

- **The clip.** Generated into a temporary folder: the ``hard`` preset, 40 frames (the preset the
  cross-check was made for; ``--quick``: ``default``, 10 frames, 6 board images).
- **The runs.** It is reconstructed in one process, on one BLAS thread, with ``cross_check`` off and
  then on (the library's default). The calibration is computed by the first run and reused by the
  second (:mod:`lipgen.recon.calibcache`); each run's tracking CPU seconds are the pipeline's own
  record (``info["cpu_seconds"]["tracking"]``). The accepted share of marker sightings (truth-free,
  ``info["sightings"]``) says what the second run buys.
- **The baseline, in the same run.** ``cv2.SimpleBlobDetector`` on both views of every frame
  (detection of dark round blobs alone, which every dot tracker does at least once per frame).
  Tracking is reported as a multiple of it, and the cross-check as a multiple of one run.
"""

from __future__ import annotations

import logging
import tempfile
import time
from pathlib import Path

import numpy as np

from lipgen.bench.compare import load_average

NAME = "tracking"

log = logging.getLogger(__name__)

CLIP = {False: {"preset": "hard", "frames": 40, "calib_frames": None},
        True: {"preset": "default", "frames": 10, "calib_frames": 6}}
"""The clip per ``quick``: preset, frames, board images (None: the preset's)."""


def _blob_seconds(dataset) -> float:
    """CPU seconds of OpenCV's dark-blob detector on both views of every frame of ``dataset``."""
    import cv2

    from lipgen.recon.dots import ink_gray

    params = cv2.SimpleBlobDetector_Params()
    params.filterByColor, params.blobColor = True, 0
    params.filterByArea, params.minArea, params.maxArea = True, 3.0, 200.0
    detector = cv2.SimpleBlobDetector_create(params)
    grays = []
    for i in range(len(dataset)):
        for view in dataset.rig.split_views(np.asarray(dataset[i].image)):
            grays.append(np.ascontiguousarray(np.round(255 * ink_gray(view)).astype(np.uint8)))
    t = time.process_time()
    found = [len(detector.detect(g)) for g in grays]
    seconds = time.process_time() - t
    log.info("OpenCV blobs: %.1f per view image", float(np.mean(found)))
    return seconds


def _reconstruct(path: Path, cross_check: bool) -> dict:
    from lipgen._threads import blas_threads
    from lipgen.recon.pipeline import reconstruct_dataset
    from lipgen.recon.settings import ReconstructSettings

    with blas_threads(1):
        rec = reconstruct_dataset(path, settings=ReconstructSettings(cross_check=cross_check), progress=False)
    cpu = rec.info["cpu_seconds"]
    return {"tracking_cpu_s": float(cpu["tracking"]), "calibration_cpu_s": float(cpu["calibration"]),
            "accepted_share": float(rec.info["sightings"]["accepted_share"])}


def run(quick: bool) -> dict:
    from lipgen.dataset import Dataset
    from lipgen.dataset.generate import generate
    from lipgen.dataset.settings import GenerateSettings

    clip = CLIP[bool(quick)]
    load_before = load_average()
    with tempfile.TemporaryDirectory(prefix="lipgen_bench_tracking_") as tmp:
        path = Path(tmp) / "clip"
        settings = GenerateSettings.from_preset(clip["preset"], frames=clip["frames"], seed=0,
                                                calib_frames=clip["calib_frames"])
        generate(path, settings, progress=False)
        once = _reconstruct(path, cross_check=False)       # calibrates: the next run reuses it
        twice = _reconstruct(path, cross_check=True)
        base = _blob_seconds(Dataset(path))
    n = clip["frames"]
    per_frame = {"opencv_blobs": base / n, "track_once": once["tracking_cpu_s"] / n,
                 "track_cross_checked": twice["tracking_cpu_s"] / n}
    floor = max(per_frame["opencv_blobs"], 1e-12)
    return {
        "clip": clip | {"views": 2},
        "cpu_s_per_frame": per_frame,
        "once_over_opencv_blobs": per_frame["track_once"] / floor,
        "cross_checked_over_opencv_blobs": per_frame["track_cross_checked"] / floor,
        "cross_checked_over_once": twice["tracking_cpu_s"] / max(once["tracking_cpu_s"], 1e-12),
        "calibration_cpu_s": once["calibration_cpu_s"],
        "accepted_share": {"once": once["accepted_share"], "cross_checked": twice["accepted_share"]},
        "load_average": {"before": load_before, "after": load_average()},
        "note": "CPU seconds on one BLAS thread; the baseline (OpenCV's SimpleBlobDetector on both views "
                "of every frame) measured in the same run; the calibration computed once",
    }
