"""A user's own camera-mirror recording in the dataset layout: video frames, no truth.

``lipgen recording init`` (:mod:`lipgen.recon.recording`) writes the documented layout from a
video and a folder of chessboard photos: ``raw/NNNNNN.png`` (the video's frames), ``calib/NNNNNN.png``
(the photos), ``mesh.npz`` (the model mesh whose marker layout was inked on the lips) and a
manifest with ``"source": "recording"``, the :class:`RecordingSettings` and no truth files.
Everything that does not compare with the truth reads it like a synthetic dataset.

Videos are decoded with imageio-ffmpeg (``pip install 'lipgen[vision]'``).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

from lipgen._optional import require
from lipgen.errors import DatasetError

__all__ = ["RECORDING", "IMAGE_SUFFIXES", "RecordingSettings", "read_video", "video_info", "frame_files",
           "source_info", "read_source", "recording_manifest"]

RECORDING = "recording"
"""The manifest's ``source`` for a user's recording (a synthetic dataset has none)."""

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")
"""File suffixes read as images (calibration photos, frames of a frame folder)."""


@dataclass(frozen=True)
class RecordingSettings:
    """What describes a recording (the counterpart of :class:`~lipgen.dataset.layout.GenerateSettings`).

    Attributes: ``frames``, ``size`` (W, H), ``fps``, ``calib_frames``, ``board`` (inner cols,
    inner rows, square mm), ``dot_diameter`` (mm, of the ink dots), ``video`` (source file name),
    ``calib_sources`` (the photos' file names, in calib/ order), ``mirror_side``, ``split``.
    """

    frames: int
    size: tuple[int, int]
    fps: float
    calib_frames: int
    board: tuple[int, int, float] = (9, 6, 8.0)
    dot_diameter: float = 2.0
    video: str = ""
    calib_sources: tuple[str, ...] = ()
    mirror_side: str = "left"
    split: int = 0

    def __post_init__(self) -> None:
        w, h = (int(x) for x in self.size)
        if self.frames < 1 or w < 16 or h < 12 or self.calib_frames < 0:
            raise ValueError(f"a recording needs frames >= 1 and a size of at least 16x12, got {self.frames} "
                             f"frames of {w}x{h}")
        if self.mirror_side not in ("left", "right") or not 0 < int(self.split) < w:
            raise ValueError(f"mirror_side must be 'left' or 'right' and split a column in (0, {w}), got "
                             f"{self.mirror_side!r}, {self.split!r}")
        if not 0.2 <= float(self.dot_diameter) <= 10 or not 1 <= float(self.fps) <= 1000:
            raise ValueError(f"dot_diameter must be in [0.2, 10] mm and fps in [1, 1000], got "
                             f"{self.dot_diameter}, {self.fps}")
        c, r, sq = self.board
        object.__setattr__(self, "size", (w, h))
        object.__setattr__(self, "board", (int(c), int(r), float(sq)))
        object.__setattr__(self, "calib_sources", tuple(str(s) for s in self.calib_sources))

    def to_dict(self) -> dict:
        """The settings as a JSON-ready dict (as stored in the manifest)."""
        d = asdict(self)
        d["size"], d["board"] = list(self.size), list(self.board)
        d["calib_sources"] = list(self.calib_sources)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> RecordingSettings:
        """Settings from a manifest's dict, checking every key."""
        known = {f.name for f in fields(cls)}
        if set(d) - known:
            raise ValueError(f"unknown recording settings {sorted(set(d) - known)}")
        return cls(**{k: tuple(v) if k in ("size", "board", "calib_sources") else v for k, v in d.items()})


def video_info(path) -> dict:
    """``{"size": (W, H), "fps": float, "frames": int or None}`` of a video, or a
    :class:`DatasetError` naming the file when it cannot be decoded."""
    iio = require("imageio_ffmpeg", "reading video")
    p = Path(path)
    if not p.is_file():
        raise DatasetError(f"{p}: no such video file")
    try:
        reader = iio.read_frames(str(p))
        meta = next(reader)
        reader.close()
    except (RuntimeError, OSError, StopIteration, ValueError) as exc:
        raise DatasetError(f"{p} cannot be decoded as a video: {str(exc).strip().splitlines()[-1]}") from None
    n = meta.get("nframes")
    return {"size": tuple(int(v) for v in meta["size"]), "fps": float(meta.get("fps") or 30.0),
            "frames": int(n) if isinstance(n, int | float) and np.isfinite(n) else None}


def read_video(path) -> Iterator[np.ndarray]:
    """The frames of a video, one (H, W, 3) uint8 RGB array at a time (decoded by ffmpeg)."""
    iio = require("imageio_ffmpeg", "reading video")
    info = video_info(path)
    W, H = info["size"]
    reader = iio.read_frames(str(path), pix_fmt="rgb24")
    try:
        next(reader)
        for buf in reader:
            frame = np.frombuffer(buf, dtype=np.uint8)
            if frame.size != W * H * 3:
                raise DatasetError(f"{path}: a decoded frame has {frame.size} bytes, not {W}x{H}x3")
            yield frame.reshape(H, W, 3)
    except RuntimeError as exc:
        raise DatasetError(f"{path}: decoding failed part-way: {str(exc).strip().splitlines()[-1]}") from None
    finally:
        reader.close()


def frame_files(folder) -> list[Path]:
    """The image files of a frame folder, in name order, checked to share one size.

    Only the image headers are read. A :class:`DatasetError` names the first file whose size
    differs from the first frame's, or an unreadable file.

    Returns
    -------
    list of Path
    """
    from PIL import Image, UnidentifiedImageError

    d = Path(folder)
    files = sorted(p for p in d.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())
    if not files:
        raise DatasetError(f"{d} holds no frames ({', '.join(IMAGE_SUFFIXES)}); give a video file or a "
                           "folder of frame images")
    size = None
    for f in files:
        try:
            with Image.open(f) as im:
                this = im.size
        except (UnidentifiedImageError, OSError) as exc:
            raise DatasetError(f"{f} is not a readable image: {exc}") from None
        if size is None:
            size = this
        elif this != size:
            raise DatasetError(f"{f} is {this[0]}x{this[1]} but {files[0].name} is {size[0]}x{size[1]}: the "
                               "frames of a recording must share one size (frames of mixed sizes)")
    return files


def source_info(path, fps: float | None = None) -> dict:
    """:func:`video_info` of a video file, or the same of a folder of frame images.

    A folder has no frame rate of its own: ``fps`` (default 30) is used; for a video ``fps``, when
    given, overrides the file's.
    """
    p = Path(path)
    if p.is_dir():
        files = frame_files(p)
        from PIL import Image

        with Image.open(files[0]) as im:
            size = tuple(int(v) for v in im.size)
        return {"size": size, "fps": float(fps or 30.0), "frames": len(files)}
    info = video_info(p)
    return {**info, "fps": float(fps or info["fps"])}


def read_source(path) -> Iterator[np.ndarray]:
    """The frames of a video file or of a folder of frame images, one (H, W, 3) uint8 RGB array at a time."""
    p = Path(path)
    if not p.is_dir():
        yield from read_video(p)
        return
    from PIL import Image

    for f in frame_files(p):
        with Image.open(f) as im:
            yield np.asarray(im.convert("RGB"))


def recording_manifest(s: RecordingSettings, rig, mesh, version: str) -> dict:
    """The manifest of a recording: the dataset layout with ``"source": "recording"``, no truth files,
    ``rig`` the calibrated rig (world: the board in calibration image 0) and the model mesh's markers."""
    from lipgen.dataset.checks import FORMAT, SCHEMA
    from lipgen.rig.camera import VIEWS

    return {
        "format": FORMAT, "schema_version": SCHEMA, "lipgen_version": version, "units": "mm",
        "convention": "opencv", "source": RECORDING,
        "pixels": "pixel (0, 0) is the centre of the top-left pixel; uv = (column, row)",
        "seed": None, "fps": s.fps, "settings": s.to_dict(), "rig": rig.to_dict(),
        "rig_note": "calibrated from calib/ by lipgen recording init; lipgen reconstruct calibrates again",
        "views": list(VIEWS),
        "mesh": {"file": "mesh.npz", "name": mesh.name, "topology_id": mesh.topology_id, "resolution": 0,
                 "n_nodes": mesh.n_nodes, "n_faces": mesh.n_faces, "marker_names": list(mesh.marker_names),
                 "regions": list(mesh.region_names),
                 "role": "the model mesh whose marker layout is inked on the lips (no subject mesh)"},
        "marks": list(mesh.marker_names) + ["nose"], "actions": [],
        "frames": [{"index": i, "time": i / s.fps, "raw": f"raw/{i:06d}.png"} for i in range(s.frames)],
        "calibration": {
            "board": {"type": "chessboard", "inner_cols": s.board[0], "inner_rows": s.board[1],
                      "square": s.board[2]},
            "frames": [{"index": i, "raw": f"calib/{i:06d}.png", "source": src}
                       for i, src in enumerate(s.calib_sources)]},
    }
