"""``lipgen recording init``: a user's camera-mirror footage and chessboard photos -> the dataset layout.

The footage is a video file or a folder of frame images (in name order).

The layout is :mod:`lipgen.dataset.footage` (no truth). Which half of the frame is the mirror and
where the split column lies are given, or detected:

* **split**: the mirror's edge is a sharp change of brightness down the whole frame (a mirror
  reflects less than all light); the column of the largest median step between neighbouring
  columns, in the middle half of the calibration photos.
* **mirror side**: the darker half (a mirror reflects less than all light; a back-silvered one
  about 85-95 %) when the halves' mean brightness differs by at least 3 % over the calibration
  photos; otherwise the command asks for ``--mirror-side``. The calibration cannot tell: a
  chessboard seen in a mirror is again a chessboard, and the rig with the halves swapped fits the
  corners exactly as well (measured: 0.11 px RMS either way on a rendered rig), but it would mirror
  the face, swapping the left and right markers.

Every input is checked before anything is written: the video decodes (or every frame image is
readable), all photos and frames share
one size, at least 4 photos show the whole board in both views. The folder is written under a
temporary name and renamed at the end, so a failure leaves nothing behind.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np

from lipgen.dataset.footage import IMAGE_SUFFIXES, RECORDING
from lipgen.errors import DatasetError

__all__ = ["IMAGE_SUFFIXES", "init_recording", "detect_split", "detect_mirror_side", "calibration_photos"]

log = logging.getLogger(__name__)


def calibration_photos(folder, size: tuple[int, int]) -> tuple[list[Path], list[np.ndarray]]:
    """The chessboard photos in ``folder`` (sorted by name), as RGB arrays of ``size (W, H)``."""
    from PIL import Image, UnidentifiedImageError

    d = Path(folder)
    if not d.is_dir():
        raise DatasetError(f"{d}: no calibration folder; give --calib a folder of chessboard photos taken "
                           "with the same camera and mirror")
    files = sorted(p for p in d.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())
    if not files:
        raise DatasetError(f"{d} holds no calibration images ({', '.join(IMAGE_SUFFIXES)}); take at least 4 "
                           "photos of the chessboard seen directly and in the mirror")
    images = []
    for f in files:
        try:
            with Image.open(f) as im:
                img = np.asarray(im.convert("RGB"))
        except (UnidentifiedImageError, OSError) as exc:
            raise DatasetError(f"{f} is not a readable image: {exc}") from None
        if (img.shape[1], img.shape[0]) != tuple(size):
            raise DatasetError(f"{f} is {img.shape[1]}x{img.shape[0]} but the recording's frames are "
                               f"{size[0]}x{size[1]}: the photos must come from the same camera at the same "
                               "resolution (frames of mixed sizes)")
        images.append(img)
    return files, images


def detect_split(images) -> int:
    """The mirror's edge: the column (in the middle half) with the largest median brightness step."""
    gray = np.mean([np.asarray(im, float).mean(-1) if np.ndim(im) == 3 else np.asarray(im, float)
                    for im in images], axis=0)
    step = np.abs(np.median(np.diff(gray, axis=1), axis=0))          # between column c and c + 1
    W = gray.shape[1]
    lo, hi = W // 4, 3 * W // 4
    return int(lo + np.argmax(step[lo:hi]) + 1)


def _layout(size, side: str, split: int):
    """A MirrorRig carrying only the image layout (size, side, split) for :func:`calibrate_rig`."""
    from lipgen.rig.camera import MirrorRig
    from lipgen.rig.pinhole import PinholeCamera

    W, H = size
    K = np.array([[float(W), 0, (W - 1) / 2], [0, float(W), (H - 1) / 2], [0, 0, 1]])
    cam = PinholeCamera(K, np.eye(3), np.zeros(3), W, H, None, "real")
    x = -1.0 if side == "left" else 1.0          # a mirror plane beside the camera, on that side
    return MirrorRig(cam, np.array([-x, 0.0, 0.0]), -150.0, side, split)


def detect_mirror_side(images, split: int, min_contrast: float = 0.03) -> tuple[str | None, float]:
    """(side, ratio): the darker half is the mirror when the ratio of the darker half's mean
    brightness to the other's is below ``1 - min_contrast``; side None when it is not."""
    gray = np.mean([np.asarray(im, float).mean(-1) for im in images], axis=0)
    left, right = gray[:, :split].mean(), gray[:, split:].mean()
    ratio = min(left, right) / max(max(left, right), 1e-9)
    if ratio > 1 - min_contrast:
        return None, float(ratio)
    return ("left" if left < right else "right"), float(ratio)


def check_recording_out(out: Path, video, calib, force: bool, flag: str = "--out") -> None:
    """Refuse recording folder ``out`` before any work when it may not be (re)placed: its parent is
    missing, it holds (or lies inside) the footage or the photos, or it is a non-empty folder that
    is not a dataset (``force`` replaces a dataset or recording only: never a folder of other files)."""
    dest = out.resolve()
    for what, src in (("the footage", video), ("--calib", calib)):
        src = Path(src).resolve()
        if dest == src or src.is_relative_to(dest) or dest.is_relative_to(src):
            raise ValueError(f"{flag} {out} overlaps {what} {src} (the same folder, inside it or holding "
                             "it); the recording would replace its own input; choose another folder "
                             "(nothing was written)")
    if not out.parent.is_dir():
        raise FileNotFoundError(f"{flag} {out}: folder {out.parent} does not exist; create it first or "
                                "choose another path (nothing was written)")
    if not os.access(out.parent, os.W_OK | os.X_OK):  # the recording is built beside it: before calibrating
        raise PermissionError(f"{flag} {out}: folder {out.parent} is not writable; choose another path "
                              "(nothing was written)")
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"{flag} {out} is a file, not a folder; choose a folder")
    if out.is_dir() and any(out.iterdir()):
        if not (out / "manifest.json").is_file():
            raise FileExistsError(f"{flag} {out} holds other files (no manifest.json: not a dataset); "
                                  "--force replaces a recording only; choose a new or empty folder")
        if not force:
            raise FileExistsError(f"{out} exists and is not empty; choose another {flag} or pass --force")
        try:
            source = json.loads((out / "manifest.json").read_text()).get("source")
        except (OSError, ValueError, AttributeError):
            source = None
        if source != RECORDING:  # a generated dataset holds truth that --force must not delete
            raise FileExistsError(f"{flag} {out} holds a dataset that is not a recording (manifest source "
                                  f"{source!r}); --force replaces a recording only; choose another folder "
                                  "(nothing was written)")


def init_recording(video, calib, out, mirror_side: str = "auto", split: int | str = "auto",
                   board=(9, 6, 8.0), dot_diameter: float = 2.0, mesh_source: str = "lip_mesh(0)",
                   force: bool = False, progress: bool = False, fps: float | None = None,
                   out_flag: str = "--out") -> dict:
    """Build a recording folder ``out`` from ``video`` and the chessboard photos in ``calib``
    (``out_flag``: how the caller's user named ``out``, for the messages).

    ``video`` is a video file or a folder of frame images (name order; ``fps``, default 30, is
    then their frame rate; for a video it overrides the file's).

    Returns a summary: ``frames``, ``size``, ``fps``, ``mirror_side``, ``split``,
    ``brightness_ratio`` (mirror half / direct half), ``calibration_rms_px``, ``calibration``
    (per-image RMS, dropped images).
    """
    from lipgen import __version__
    from lipgen.dataset.footage import RecordingSettings, read_source, recording_manifest, source_info
    from lipgen.recon.calibcache import calibrated
    from lipgen.recon.pipeline import model_mesh
    from lipgen.rig.target import Chessboard

    out = Path(out)
    check_recording_out(out, video, calib, force, out_flag)
    if mirror_side not in ("auto", "left", "right"):
        raise ValueError(f"mirror_side must be 'auto', 'left' or 'right', got {mirror_side!r}")
    if fps is not None and not 1 <= float(fps) <= 1000:
        raise ValueError(f"fps must be in [1, 1000], got {fps}")
    if not 0.2 <= float(dot_diameter) <= 10:  # as RecordingSettings, but before the calibration
        raise ValueError(f"dot_diameter must be in [0.2, 10] mm, got {dot_diameter}")
    mesh = model_mesh(mesh_source)  # a bad --mesh: named before the calibration, not after
    info = source_info(video, fps)
    size = info["size"]
    files, photos = calibration_photos(calib, size)
    if len(photos) < 4:
        raise DatasetError(f"{calib} holds {len(photos)} calibration image(s); the calibration needs at "
                           "least 4 photos showing the whole chessboard, directly and in the mirror")
    col = detect_split(photos) if split == "auto" else int(split)
    if not 0 < col < size[0]:
        raise ValueError(f"split must be a column in (0, {size[0]}), got {col}")
    chess = Chessboard(*board)
    side, ratio = detect_mirror_side(photos, col)
    if mirror_side == "auto":
        if side is None:
            raise DatasetError(f"cannot tell which side the mirror is on from {calib} (the halves' "
                               f"brightness differs by only {100 * abs(1 - ratio):.1f}%); pass --mirror-side "
                               "left or right")
        mirror_side = side
    elif side is not None and side != mirror_side:
        log.warning("--mirror-side %s, but the %s half is the darker (%.1f%% less light), as a mirror is",
                    mirror_side, side, 100 * (1 - ratio))
    cal = calibrated(photos, _layout(size, mirror_side, col), chess)  # reconstruct reuses it (calibcache)
    for d in cal.dropped:
        log.warning("calibration photo %s: %s view left out (%.2f px RMS)", files[d["image"]].name, d["view"],
                    d["rms_px"])
    settings = RecordingSettings(frames=info["frames"] or 1, size=size, fps=info["fps"],
                                 calib_frames=len(photos),
                                 board=(chess.inner_cols, chess.inner_rows, chess.square),
                                 dot_diameter=dot_diameter, video=Path(video).name,
                                 calib_sources=[f.name for f in files], mirror_side=mirror_side, split=col)
    tmp = out.with_name(f".{out.name}.part{os.getpid()}")
    if tmp.exists():
        shutil.rmtree(tmp)
    try:
        n = _write(tmp, video, photos, size, read_source, progress)
        settings = replace(settings, frames=n)
        mesh.save(tmp / "mesh.npz")
        manifest = recording_manifest(settings, cal.rig, mesh, __version__)
        (tmp / "manifest.json").write_text(json.dumps(manifest, indent=1))
        if out.exists():
            shutil.rmtree(out)
        tmp.rename(out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return {"frames": n, "size": list(size), "fps": info["fps"], "mirror_side": mirror_side, "split": col,
            "brightness_ratio": ratio, "calibration_rms_px": cal.rms, "calibration": {"per_image_rms_px": [
                {**p, "file": files[p["image"]].name} for p in cal.per_image],
                "dropped": [{**d, "file": files[d["image"]].name} for d in cal.dropped]}}


def _write(root: Path, video, photos, size, read_video, progress: bool) -> int:
    """Write calib/ and raw/ under ``root``; returns the number of video frames."""
    from PIL import Image

    (root / "calib").mkdir(parents=True)
    (root / "raw").mkdir()
    for i, img in enumerate(photos):
        Image.fromarray(img).save(root / "calib" / f"{i:06d}.png", compress_level=1)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(desc="frames", unit="frame")
    n = 0
    for n, frame in enumerate(read_video(video), start=1):
        if (frame.shape[1], frame.shape[0]) != tuple(size):
            raise DatasetError(f"{video}: frame {n - 1} is {frame.shape[1]}x{frame.shape[0]}, not {size[0]}x"
                               f"{size[1]} (frames of mixed sizes)")
        Image.fromarray(frame).save(root / "raw" / f"{n - 1:06d}.png", compress_level=1)
        if bar is not None:
            bar.update()
    if bar is not None:
        bar.close()
    if n == 0:
        raise DatasetError(f"{video} holds no frames")
    return n
