"""The rig's calibration, computed once per process for the same chessboard images.

``lipgen reconstruct FOOTAGE --calib PHOTOS`` calibrates the photos when it builds the recording
(:func:`lipgen.recon.recording.init_recording`) and again when it reconstructs it
(:func:`lipgen.recon.pipeline.reconstruct_dataset`); a script or a test session that reconstructs
several copies of one dataset calibrates the same images each time. The calibration is most of a
short clip's reconstruction (8 frames at 640x480 with 5 board images: 3.9 of 6.8 s of CPU), so
:func:`calibrated` keeps the last few results, keyed by everything
:func:`lipgen.recon.calibrate.calibrate_rig` reads: the images' bytes, the image layout (size,
mirror side, split column; the layout's cameras are never read), the boards and the options.
A result is the one a fresh calibration gives (it is deterministic, and both callers run it on one
BLAS thread); each caller gets its own copy. ``LIPGEN_CALIBRATION_CACHE=off`` turns it off.
"""

from __future__ import annotations

import copy
import hashlib
import logging
import os
import threading
from collections import OrderedDict
from collections.abc import Sequence

import numpy as np

from lipgen._threads import blas_threads
from lipgen.recon.calibrate import RigCalibration, _boards, calibrate_rig
from lipgen.rig.camera import MirrorRig

__all__ = ["calibrated", "CACHE_ENV", "CACHE_SIZE"]

log = logging.getLogger(__name__)

CACHE_ENV = "LIPGEN_CALIBRATION_CACHE"
"""Set to ``off`` to calibrate every time (to measure what the cache buys)."""

CACHE_SIZE = 4
"""Calibrations kept per process (each is a few kB: a rig and per-image errors)."""

_CACHE: OrderedDict[bytes, RigCalibration] = OrderedDict()
_LOCK = threading.Lock()  # the add-on and scripts may calibrate from several threads


def _key(frames: list[np.ndarray], layout: MirrorRig, boards: list, options: dict) -> bytes:
    """A digest of every input of :func:`calibrate_rig` that its result depends on."""
    h = hashlib.blake2b(digest_size=32)
    cam = layout.camera
    h.update(repr((cam.width, cam.height, layout.mirror_side, layout.split, len(frames))).encode())
    h.update(repr(boards).encode())  # frozen dataclasses: every field
    h.update(repr(sorted(options.items())).encode())
    for f in frames:
        a = np.ascontiguousarray(f)
        h.update(repr((a.shape, a.dtype.str)).encode())
        h.update(a.data)
    return h.digest()


def calibrated(raw_frames: Sequence, layout: MirrorRig, board, **options) -> RigCalibration:
    """:func:`lipgen.recon.calibrate.calibrate_rig` on one BLAS thread, or a copy of its result for
    the same inputs earlier in this process.

    Parameters
    ----------
    raw_frames : sequence of (H, W[, 3]) arrays
        The chessboard images, as for :func:`calibrate_rig`.
    layout : MirrorRig
        Its image layout (size, mirror side, split column).
    board : Chessboard or sequence of Chessboard
        The board, or one per image.
    **options
        Further keyword arguments of :func:`calibrate_rig` (they are part of the key).

    Returns
    -------
    RigCalibration
        A copy the caller may change.
    """
    frames = [np.asarray(f) for f in raw_frames]
    boards = _boards(board, len(frames))  # once: an iterator of boards is read here only
    if os.environ.get(CACHE_ENV) == "off":
        with blas_threads(1):  # a small bundle adjustment (lipgen._threads)
            return calibrate_rig(frames, layout, boards, **options)
    key = _key(frames, layout, boards, options)
    with _LOCK:
        hit = _CACHE.get(key)
        if hit is not None:
            _CACHE.move_to_end(key)
            hit = copy.deepcopy(hit)
    if hit is not None:
        log.info(
            "calibration: the same %d images as earlier in this process; their calibration is reused",
            len(frames),
        )
        return hit
    with blas_threads(1):
        cal = calibrate_rig(frames, layout, boards, **options)
    with _LOCK:
        _CACHE[key] = copy.deepcopy(cal)
        while len(_CACHE) > CACHE_SIZE:
            _CACHE.popitem(last=False)
    return cal
