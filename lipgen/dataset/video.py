"""A dataset's frames as one H.264 video (imageio-ffmpeg, whose wheel ships ffmpeg).

:func:`write_video` encodes the raw frames in order (x264, one thread, so the same frames give
the same bytes); :func:`read_video_frames` reads any video back as RGB frames, in order.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from lipgen._io import atomic_path
from lipgen._optional import require

__all__ = ["VIDEO_CODECS", "write_video", "read_video_frames", "check_video_codec"]

VIDEO_CODECS = {"h264": "libx264"}  # names as lipgen.rig.conditions.VIDEO_CODECS
"""Video codecs ``generate`` writes, by name, and the ffmpeg encoder used."""


def check_video_codec(codec: str) -> None:
    """Raise unless ``codec`` is one of :data:`VIDEO_CODECS` and this ffmpeg can encode it.

    Raises
    ------
    ValueError
        Unknown codec, or ffmpeg lacks its encoder.
    MissingDependencyError
        imageio-ffmpeg is not installed.
    """
    if codec not in VIDEO_CODECS:
        raise ValueError(f"unknown video codec {codec!r}; choose one of {sorted(VIDEO_CODECS)}")
    iio = require("imageio_ffmpeg", f"writing {codec} video")
    import subprocess

    encoders = subprocess.run([iio.get_ffmpeg_exe(), "-hide_banner", "-encoders"], capture_output=True,
                              text=True, check=False).stdout
    if VIDEO_CODECS[codec] not in encoders:
        raise ValueError(f"this ffmpeg ({iio.get_ffmpeg_exe()}) has no {VIDEO_CODECS[codec]} encoder for "
                         f"{codec}; install imageio-ffmpeg's wheel (pip install 'lipgen[video]')")


def write_video(path, frames: Iterable[np.ndarray], fps: float, codec: str = "h264", crf: int = 18) -> Path:
    """Encode RGB uint8 frames ``(H, W, 3)`` (all one size, even sides) to ``path`` atomically.

    ``crf`` is x264's constant rate factor: 0 lossless, 18 visually lossless, 23 its default,
    51 worst.
    """
    check_video_codec(codec)
    if isinstance(crf, bool) or not isinstance(crf, int | np.integer) or not 0 <= crf <= 51:
        raise ValueError(f"crf must be a whole number in [0, 51], got {crf!r}")
    iio = require("imageio_ffmpeg", "writing video")
    path = Path(path)
    it = iter(frames)
    first = next(it, None)
    if first is None:
        raise ValueError("no frames to write")
    h, w = first.shape[:2]
    if first.shape != (h, w, 3) or first.dtype != np.uint8 or h % 2 or w % 2:
        raise ValueError(f"frames must be (H, W, 3) uint8 with even H and W, got {first.shape} {first.dtype}")
    with atomic_path(path) as tmp:
        writer = iio.write_frames(str(tmp), (w, h), fps=fps, codec=VIDEO_CODECS[codec], macro_block_size=1,
                                  quality=None, output_params=["-crf", str(int(crf)), "-threads", "1",
                                                               "-preset", "medium", "-f", "mp4"])
        writer.send(None)
        try:
            writer.send(np.ascontiguousarray(first))
            for k, frame in enumerate(it, 1):
                if frame.shape != first.shape or frame.dtype != np.uint8:
                    raise ValueError(f"frame {k} is {frame.shape} {frame.dtype}, not {first.shape} uint8")
                writer.send(np.ascontiguousarray(frame))
        finally:
            writer.close()
    return path


def read_video_frames(path) -> Iterator[np.ndarray]:
    """The frames of a video file, in order, as ``(H, W, 3)`` uint8 RGB arrays."""
    iio = require("imageio_ffmpeg", "reading video")
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no video file {path}")
    gen = iio.read_frames(str(path), pix_fmt="rgb24")
    meta = next(gen)
    w, h = meta["size"]
    try:
        for buf in gen:
            yield np.frombuffer(buf, np.uint8).reshape(h, w, 3)
    finally:
        gen.close()
