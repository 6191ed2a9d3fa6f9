"""A held-out NRSfM set from public motion capture: CMU clips filmed orthographically.

The standard NRSfM sequences (drink, pickup, yoga, stretch, dance) were made from the CMU Graphics
Lab motion-capture library. These are *other* clips of that library (running, walking, basketball,
soccer, ...), stored as BVH windows in ``lipgen/nrsfm/data/cmu`` (provenance in its README). Each
clip's points are its skeleton's joints and end sites (:func:`lipgen.nrsfm.bvh.joint_positions`),
without those at zero offset from their parent, at every second frame (60 Hz); it is filmed
twice, by :func:`lipgen.nrsfm.validation.film_orthographic` with seeds ``2000 + i`` and
``2100 + i``. Methods are only scored on them, never tuned.
"""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np

from .bvh import BvhSkeleton, joint_positions, parse_bvh
from .validation import HumanSequence, film_orthographic

__all__ = ["CLIPS", "DATA", "assemble_window", "load_clip", "clip_points", "mocap_sequence", "mocap_set"]

DATA = Path(__file__).resolve().parent / "data" / "cmu"
"""Where the clips are kept (``<name>.bvh.gz``)."""

CLIPS = {
    "run0901": ("009/09_01.bvh", "run"),
    "walk0701": ("007/07_01.bvh", "walk"),
    "basket0603": ("006/06_03.bvh", "basketball"),
    "soccer1006": ("010/10_06.bvh", "soccer"),
    "s16t57": ("016/16_57.bvh", "subject 16, trial 57"),
    "s20t06": ("020/20_06.bvh", "subject 20, trial 6"),
}
"""Clip name -> (path in the CMU BVH conversion, activity)."""

SEEDS = (2000, 2100)
"""Each clip ``i`` is filmed with seeds ``SEEDS[j] + i``."""

STEP = 2
"""Every ``STEP``-th frame is kept (120 Hz -> 60 Hz)."""


def assemble_window(head: str, body: str) -> str:
    """BVH text of a window of frames cut from a long file.

    Parameters
    ----------
    head : str
        The file's beginning, holding the whole hierarchy and the ``MOTION`` header.
    body : str
        A contiguous run of the file from later on (it may start and end inside lines: the partial
        first and last lines are dropped), or "" to keep ``head``'s own whole frame lines.

    Returns
    -------
    str
        The hierarchy, ``MOTION``, ``Frames:`` (the window's count), ``Frame Time:``, the frames.
    """
    if "MOTION" not in head:
        raise ValueError("head holds no MOTION section: give the file's beginning, hierarchy included")
    hierarchy, motion = head.split("MOTION", 1)
    header = [ln for ln in motion.splitlines() if ln.strip()]
    time = next((ln for ln in header if ln.startswith("Frame Time:")), None)
    if time is None:
        raise ValueError("head's MOTION section has no 'Frame Time:' line")
    if body:
        lines = body.split("\n")[1:-1]          # whole lines only
    else:
        lines = [ln for ln in header if not ln.startswith(("Frames:", "Frame Time:"))]
        lines = lines[:-1] if not motion.endswith("\n") else lines
    lines = [ln for ln in lines if ln.strip()]
    return f"{hierarchy}MOTION\nFrames: {len(lines)}\n{time}\n" + "\n".join(lines) + "\n"


def load_clip(name: str, folder: Path | None = None) -> BvhSkeleton:
    """The stored clip ``name`` (a key of :data:`CLIPS`), parsed."""
    if name not in CLIPS:
        raise ValueError(f"unknown clip {name!r}; the clips are {', '.join(CLIPS)}")
    path = (DATA if folder is None else Path(folder)) / f"{name}.bvh.gz"
    if not path.is_file():
        raise FileNotFoundError(f"{path}: clip {name!r} is not stored; see {DATA / 'README.md'}")
    return parse_bvh(gzip.decompress(path.read_bytes()).decode("ascii"))


def clip_points(skeleton: BvhSkeleton, step: int = STEP) -> np.ndarray:
    """The clip's points: joints and end sites not at zero offset from their parent, every ``step``-th frame.

    Returns
    -------
    (F, P, 3) float
        World points in the file's units, y up.
    """
    keep = np.flatnonzero((skeleton.parents < 0) | (np.linalg.norm(skeleton.offsets, axis=1) > 1e-9))
    return joint_positions(skeleton)[::step][:, keep]


def mocap_sequence(name: str, seed: int, folder: Path | None = None) -> HumanSequence:
    """Clip ``name`` filmed orthographically with ``seed`` (:func:`film_orthographic`)."""
    return _filmed(name, load_clip(name, folder), seed)


def _filmed(name: str, skeleton: BvhSkeleton, seed: int) -> HumanSequence:
    """The parsed clip ``name`` filmed with ``seed`` (see :func:`mocap_sequence`)."""
    X = clip_points(skeleton)
    rng = np.random.default_rng(seed)
    t = np.arange(len(X)) * STEP * skeleton.frame_time
    W, S, R, degrees = film_orthographic(X, rng, t)
    return HumanSequence(name=f"cmu-{name}-{seed}", W=W, S=S, R=R, motion=CLIPS[name][1],
                         degrees_per_frame=degrees, seed=seed)


def mocap_set(clips=None, folder: Path | None = None) -> list[HumanSequence]:
    """The clips (default: all of :data:`CLIPS`), each filmed with each of :data:`SEEDS`; clip ``i``
    of :data:`CLIPS` always gets seeds ``SEEDS[j] + i``, whichever clips are asked for."""
    names = list(CLIPS) if clips is None else list(clips)
    unknown = [n for n in names if n not in CLIPS]
    if unknown:
        raise ValueError(f"unknown clip(s) {unknown}; the clips are {', '.join(CLIPS)}")
    index = {n: i for i, n in enumerate(CLIPS)}
    skeletons = {n: load_clip(n, folder) for n in names}  # each file parsed once, filmed once per seed
    return [_filmed(n, skeletons[n], base + index[n]) for base in SEEDS for n in names]
