"""Writing a lip sync: USD (blend shapes + the audio), ``.npz`` or ``.csv``, atomically.

- **USD** (``.usda``, ``.usdc``, ``.usd``): the mode animation exactly as :func:`lipgen.usd.export_usd`
  writes it (frame ``f`` at time code ``start + f``), plus ``/Lips/Speech``, a
  ``UsdMedia.SpatialAudio`` prim that plays the WAV (``auralMode = nonSpatial``,
  ``playbackMode = onceFromStartToEnd``) from time code ``start``, so that audio time 0 is
  frame 0; its ``filePath`` is relative to the USD file when they share a folder tree.
- **USDZ** (``.usdz``): the same stage packaged with the WAV inside (one file to hand on); the
  prim's ``filePath`` names the WAV in the package.
- **npz**: ``coefficients`` (F, k), ``activations`` (F, A), ``actions``, ``times`` (F,) s,
  ``fps``, ``phones`` / ``phone_start`` / ``phone_end`` (s), ``phone_source``,
  ``confidence``, ``text``.
- **csv**: one row a frame: ``frame,time_s,mode00,...``.
"""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path

import numpy as np

from lipgen._io import atomic_path
from lipgen.speech.lipsync import LipSync
from lipgen.subject.activation import ACTIONS

__all__ = ["OUTPUT_EXTENSIONS", "check_output", "write_lipsync", "add_audio_prim"]

OUTPUT_EXTENSIONS = (".usda", ".usdc", ".usd", ".usdz", ".npz", ".csv")
"""The file types a lip sync is written to (chosen by the extension)."""


def check_output(path: str | os.PathLike, force: bool = False) -> Path:
    """The output path, checked before any work: a known extension, an existing folder, and no
    existing file unless ``force``."""
    p = Path(path)
    if p.suffix.lower() not in OUTPUT_EXTENSIONS:
        raise ValueError(f"cannot write a lip sync to {str(p)!r}: the extension must be one of "
                         f"{', '.join(OUTPUT_EXTENSIONS)}")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise FileNotFoundError(f"cannot write {p}: folder {parent} does not exist")
    if p.exists() and not force:
        raise FileExistsError(f"{p} exists; pass --force to overwrite it")
    return p


def add_audio_prim(stage, wav: str | os.PathLike, start: float, duration: float, fps: float,
                   usd_path: str | os.PathLike, prim_path: str = "/Lips/Speech"):
    """Author a ``UsdMedia.SpatialAudio`` playing ``wav`` from time code ``start`` on ``stage``."""
    from pxr import Sdf, UsdMedia

    wav = Path(wav).resolve()
    here = Path(usd_path).resolve().parent
    try:
        asset = os.path.relpath(wav, here)
    except ValueError:  # another drive
        asset = str(wav)
    audio = UsdMedia.SpatialAudio.Define(stage, Sdf.Path(prim_path))
    audio.CreateFilePathAttr(Sdf.AssetPath(asset.replace(os.sep, "/")))
    audio.CreateAuralModeAttr(UsdMedia.Tokens.nonSpatial)
    audio.CreatePlaybackModeAttr(UsdMedia.Tokens.onceFromStartToEnd)
    audio.CreateStartTimeAttr(Sdf.TimeCode(float(start)))
    audio.CreateEndTimeAttr(Sdf.TimeCode(float(start) + float(duration) * float(fps)))
    audio.CreateMediaOffsetAttr(0.0)
    return audio


def _npz_bytes(result: LipSync) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, coefficients=result.coefficients, activations=result.activations,
             actions=np.array(ACTIONS), times=result.times, fps=np.float64(result.fps),
             phones=np.array(result.phones.labels), phone_start=result.phones.start,
             phone_end=result.phones.end, phone_source=np.array(result.phones.source),
             confidence=np.float64(result.phones.confidence), text=np.array(result.text or ""))
    return buf.getvalue()


def _csv_text(result: LipSync) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    k = result.coefficients.shape[1]
    w.writerow(["frame", "time_s"] + [f"mode{i:02d}" for i in range(k)])
    for f, (t, row) in enumerate(zip(result.times, result.coefficients, strict=True)):
        w.writerow([f, f"{t:.6f}"] + [f"{v:.6g}" for v in row])
    return buf.getvalue()


def write_lipsync(path: str | os.PathLike, result: LipSync, mesh=None, wav: str | None = None,
                  start: int = 0, force: bool = False, weight_range: str = "signed") -> Path:
    """Write ``result`` to ``path`` (format by extension, module doc); nothing is left on failure.

    ``mesh`` (the model's LipMesh) and ``wav`` (the audio file to reference) are for USD.
    """
    dest = check_output(path, force)
    ext = dest.suffix.lower()
    if ext == ".npz":
        with atomic_path(dest) as tmp:
            tmp.write_bytes(_npz_bytes(result))
        return dest
    if ext == ".csv":
        with atomic_path(dest) as tmp:
            tmp.write_text(_csv_text(result), encoding="utf-8")
        return dest
    from pxr import Usd

    from lipgen.usd import export_usd

    if mesh is None:
        raise ValueError("USD output needs the model's mesh")
    duration = result.audio.duration if result.audio else result.n_frames / result.fps
    if ext == ".usdz":
        _write_usdz(dest, result, mesh, wav, int(start), duration, weight_range)
        return dest
    with atomic_path(dest) as tmp:
        export_usd(tmp, mesh, result.model, result.coefficients, fps=result.fps, start=int(start),
                   weight_range=weight_range)
        if wav is not None:
            stage = Usd.Stage.Open(str(tmp))
            add_audio_prim(stage, wav, start, duration, result.fps, dest)
            stage.GetRootLayer().Save()
    return dest


def _write_usdz(dest: Path, result: LipSync, mesh, wav, start: int, duration: float,
                weight_range: str) -> None:
    """A ``.usdz`` package of the lip sync's stage (``lipsync.usdc``) and the WAV it plays, if any."""
    import shutil
    import tempfile

    from pxr import Usd, UsdUtils

    from lipgen.usd import export_usd

    with atomic_path(dest) as tmp, tempfile.TemporaryDirectory(prefix=f"{tmp.name}-pkg-",
                                                               dir=tmp.parent) as work:
        root = Path(work) / "lipsync.usdc"
        export_usd(root, mesh, result.model, result.coefficients, fps=result.fps, start=start,
                   weight_range=weight_range)
        if wav is not None:
            sound = Path(work) / "speech.wav"
            shutil.copyfile(wav, sound)
            stage = Usd.Stage.Open(str(root))
            add_audio_prim(stage, sound, start, duration, result.fps, root)
            stage.GetRootLayer().Save()
            del stage
        tmp.unlink()  # the packager refuses to overwrite the empty placeholder
        if not UsdUtils.CreateNewUsdzPackage(str(root), str(tmp)):
            raise OSError(f"USD could not package {root} and {wav} into {tmp}")
