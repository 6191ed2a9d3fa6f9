"""Synthetic camera-mirror datasets on disk: the layout and the reader (:class:`Dataset`); the
settings are in :mod:`lipgen.dataset.settings`, the manifest and its checks in
:mod:`lipgen.dataset.manifest`.

Layout (DESIGN.md)::

    DATASET/manifest.json      schema version, units (mm), convention "opencv", seed, rig (real
                               camera, mirror plane, derived view cameras), mesh identity, frame
                               list, calibration target and frames, generator settings, version
    DATASET/mesh.npz           the subject's rest mesh (LipMesh.save)
    DATASET/raw/000000.png     raw frame as the camera sees it (mirror half flipped)
    DATASET/truth/000000.npz   per-frame truth (see TRUTH_FIELDS)
    DATASET/calib/000000.png   chessboard calibration frame, and calib/000000.npz its truth

Per-view arrays are in :data:`lipgen.rig.camera.VIEWS` order (virtual, real); ``uv`` are pixels of
the split, corrected views and ``uv_raw`` of the raw frame; pixel (0, 0) is the centre of the
top-left pixel. The marks are the 16 markers then the nose.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from lipgen._io import load_npz
from lipgen.dataset.checks import SCHEMA, check_relative, intact
from lipgen.dataset.manifest import (
    CALIB_KIND,
    DEPTH_KIND,
    FRAME_KIND,
    TRUTH_FIELDS,
    build_manifest,
    calib_paths,
    extra_paths,
    frame_paths,
    mask_labels,
    validate_manifest,
)
from lipgen.dataset.settings import GenerateSettings
from lipgen.errors import DatasetError, ModelFileError
from lipgen.rig.camera import VIEWS, MirrorRig

__all__ = ["Dataset", "DatasetFrame", "CalibrationFrame", "GenerateSettings", "TRUTH_FIELDS",
           "build_manifest", "validate_manifest", "frame_paths", "calib_paths", "extra_paths", "mask_labels",
           "check_relative", "intact"]


@dataclass(frozen=True, eq=False)
class DatasetFrame:
    """One frame: the raw image and its truth (``truth`` keys: :data:`TRUTH_FIELDS`; empty when the
    dataset has no truth)."""

    index: int
    time: float
    image: np.ndarray
    truth: dict

    def __getattr__(self, name):
        try:
            return self.__dict__["truth"][name]
        except KeyError:
            raise AttributeError(name) from None


@dataclass(frozen=True, eq=False)
class CalibrationFrame:
    """One calibration image and the board's true pose (world X = A p + b) and corners."""

    index: int
    image: np.ndarray
    truth: dict


class Dataset:
    """A dataset folder written by ``lipgen generate``.

    Attributes: ``path``, ``manifest`` (dict, validated), ``rig`` (:class:`MirrorRig`), ``mesh``
    (:class:`~lipgen.mesh.LipMesh`, checked against the manifest's topology id), ``fps``,
    ``marks`` (names). ``len(ds)`` frames; ``ds[i]`` and iteration give :class:`DatasetFrame`.
    """

    def __init__(self, path) -> None:
        self.path = Path(path)
        mf = self.path / "manifest.json"
        if not mf.is_file():
            raise DatasetError(f"{self.path} is not a lipgen dataset (no manifest.json)")
        try:
            self.manifest = json.loads(mf.read_text())
        except (OSError, ValueError) as exc:
            raise DatasetError(f"{mf} is not readable JSON: {exc}") from exc
        validate_manifest(self.manifest, mf)
        self.rig = MirrorRig.from_dict(self.manifest["rig"])
        self.fps = float(self.manifest["fps"])
        self.marks = tuple(self.manifest["marks"])

    def file(self, rel: str) -> Path:
        """The path of manifest entry ``rel``, refused (:class:`DatasetError`) if it resolves
        outside the dataset folder (an absolute path, ``..``, or a symlink leading out)."""
        check_relative(rel, f"{self.path}/manifest.json entry")
        p = self.path / rel
        root, target = self.path.resolve(), p.resolve()
        if not target.is_relative_to(root):
            raise DatasetError(f"{self.path}: {rel} resolves to {target}, outside the dataset folder "
                               "(a symlink leading out?); refusing to read it")
        return p

    @cached_property
    def mesh(self):
        from lipgen.mesh.lipmesh import LipMesh

        info = self.manifest["mesh"]
        try:
            mesh = LipMesh.load(self.file(info["file"]))
        except (FileNotFoundError, ModelFileError) as exc:
            raise DatasetError(f"{self.path}: cannot read the mesh: {exc}") from exc
        if mesh.topology_id != info["topology_id"]:
            raise DatasetError(f"{self.path}: mesh.npz has topology {mesh.topology_id}, the manifest says "
                               f"{info['topology_id']}")
        return mesh

    @cached_property
    def dots(self):
        """The subject's ink dots (:class:`lipgen.subject.inkdots.SurfaceDots`), or None when they
        sit on the marker nodes."""
        sub = self.manifest.get("subject")
        if not sub or sub.get("dots") is None:
            return None
        from lipgen.subject.inkdots import SurfaceDots

        try:
            return SurfaceDots.from_dict(sub["dots"], self.mesh.n_faces)
        except (KeyError, TypeError, ValueError) as exc:
            raise DatasetError(f"{self.path}: the manifest's subject dots are malformed: {exc}") from exc

    def rest_marks(self) -> np.ndarray:
        """(16, 3) the ink dots at the subject's rest (model frame, mm)."""
        if self.dots is None:
            return self.mesh.vertices[self.mesh.markers]
        from lipgen.subject.inkdots import dot_positions

        return dot_positions(self.dots, self.mesh.faces, self.mesh.vertices)

    @property
    def settings(self):
        """:class:`GenerateSettings`, or :class:`~lipgen.dataset.footage.RecordingSettings` for a
        user's recording (``manifest["source"] == "recording"``)."""
        if self.manifest.get("source") == "recording":
            from lipgen.dataset.footage import RecordingSettings

            return RecordingSettings.from_dict(self.manifest["settings"])
        return GenerateSettings.from_dict(self.manifest["settings"])

    def __len__(self) -> int:
        return len(self.manifest["frames"])

    def missing(self, verify: bool = True, truth: bool = True) -> list[int]:
        """Frames whose files are not (yet) written, or (``verify``) do not decode (empty or
        truncated); ``lipgen generate --resume`` completes them.

        With ``truth=False`` only the raw frames count: what a reconstruction needs (a recording
        of real footage has no truth, depth or masks).
        """
        kinds = {"raw": None, "truth": FRAME_KIND, "depth": DEPTH_KIND, "mask": None}
        if not truth:
            kinds = {"raw": None}
        out = []
        for i, f in enumerate(self.manifest["frames"]):
            paths = [(self.file(f[k]), kind) for k, kind in kinds.items() if k in f]
            if not all(intact(p, kind) if verify else p.is_file() for p, kind in paths):
                out.append(i)
        return out
    @cached_property
    def has_truth(self) -> bool:
        """Whether every frame and calibration frame has its ground-truth file (a synthetic dataset
        does; a user's recording, or a dataset whose ``truth/`` was removed, does not)."""
        entries = [*self.manifest["frames"], *self.manifest["calibration"]["frames"]]
        return all("truth" in f and self.file(f["truth"]).is_file() for f in entries)

    def require_truth(self, what: str) -> None:
        """Raise :class:`DatasetError` naming ``what`` (e.g. ``"lipgen evaluate"``) unless
        :attr:`has_truth`."""
        if not self.has_truth:
            n = sum("truth" in f and self.file(f["truth"]).is_file() for f in self.manifest["frames"])
            raise DatasetError(
                f"{self.path} has no ground truth ({n} of {len(self)} frames have a truth file): {what} "
                "reads the truth, so it needs a synthetic dataset from lipgen generate. "
                "lipgen reconstruct, train, show and nrsfm work without truth")

    def depth(self, i: int) -> np.ndarray:
        """(H, W) float32 depth of raw frame ``i``: each half's view-camera z, mm (the mirror half
        measures along the reflected ray, as its virtual camera sees it); NaN where no surface."""
        f = self._extra(i, "depth", "--depth")
        return load_npz(self.file(f), DEPTH_KIND, SCHEMA)["depth"]

    def mask(self, i: int) -> np.ndarray:
        """(H, W) uint8 labels of raw frame ``i``; names in ``manifest['mask_labels']`` (0 background,
        1 skin, 2 vermilion, 3 mouth, 10 + k the ink dot of mark k)."""
        from PIL import Image

        path = self.file(self._extra(i, "mask", "--masks"))
        try:
            with Image.open(path) as im:
                return np.asarray(im)
        except (OSError, SyntaxError, ValueError) as exc:
            raise DatasetError(f"{path} is not a readable PNG ({exc}); redo it with lipgen generate --resume "
                               "(same settings)") from exc

    def _extra(self, i: int, key: str, flag: str) -> str:
        f = self.manifest["frames"][i]
        if key not in f:
            raise DatasetError(f"{self.path} was generated without {key}s; regenerate with lipgen generate "
                               f"{flag}")
        if not self.file(f[key]).is_file():
            raise DatasetError(f"{self.path}: {f[key]} is missing; finish the dataset with lipgen generate "
                               "--resume (same settings)")
        return f[key]

    def _load(self, rel_png: str, rel_npz: str | None, kind: str) -> tuple[np.ndarray, dict]:
        """The image and its truth; the truth is ``{}`` when the dataset has none (:attr:`has_truth`)."""
        from PIL import Image

        png = self.file(rel_png)
        npz = None if rel_npz is None or not self.has_truth else self.file(rel_npz)
        if not png.is_file() or (npz is not None and not npz.is_file()):
            raise DatasetError(f"{self.path}: {rel_png} or {rel_npz} is missing; the dataset is incomplete. "
                               "Finish it with lipgen generate --resume (same settings)")
        try:
            with Image.open(png) as im:
                image = np.asarray(im.convert("RGB"))
        except (OSError, SyntaxError, ValueError) as exc:  # PIL: truncated or not a PNG
            raise DatasetError(f"{png} is not a readable image ({exc}); redo it with lipgen generate "
                               "--resume (same settings)") from exc
        W, H = self.rig.camera.width, self.rig.camera.height
        if image.shape[:2] != (H, W):  # named here, not as a bare shape deep in the tracking
            raise DatasetError(f"{png} is {image.shape[1]}x{image.shape[0]} but the dataset's frames are "
                               f"{W}x{H} (manifest.json): a frame of another size; restore the frame")
        return image, {} if npz is None else self._load_truth(npz, kind)

    def _load_truth(self, npz: Path, kind: str) -> dict:
        try:
            return load_npz(npz, kind, SCHEMA)
        except ModelFileError as exc:
            raise DatasetError(f"{exc}; redo it with lipgen generate --resume (same settings)") from exc

    def _entry(self, i: int) -> dict:
        n = len(self)
        if isinstance(i, bool) or not isinstance(i, int | np.integer) or not -n <= i < n:
            raise IndexError(f"frame {i!r} is out of range for a dataset of {n} frames")
        return self.manifest["frames"][int(i) % n]

    def __getitem__(self, i: int) -> DatasetFrame:
        f = self._entry(i)
        image, truth = self._load(f["raw"], f.get("truth"), FRAME_KIND)
        return DatasetFrame(int(f["index"]), float(f["time"]), image, truth)

    def truth(self, i: int) -> dict:
        """The truth of frame ``i`` alone, as ``self[i].truth`` (``{}`` when the dataset has none),
        without decoding the frame's image (a 640x480 PNG takes a few ms), so it serves where a
        raw image is missing too. The keys and shapes are :data:`SCHEMA`'s for frames (e.g.
        ``vertices`` (n, 3) mm, ``uv`` (2, P+1, 2) px, ``visible`` (2, P+1) bool).

        Raises
        ------
        IndexError
            If ``i`` is not a frame index (``-len(self) <= i < len(self)``).
        DatasetError
            If the frame's truth file is listed but missing or unreadable.
        """
        f = self._entry(i)
        if f.get("truth") is None or not self.has_truth:
            return {}
        npz = self.file(f["truth"])
        if not npz.is_file():
            raise DatasetError(f"{self.path}: {f['truth']} is missing; the dataset is incomplete. Finish it "
                               "with lipgen generate --resume (same settings)")
        return self._load_truth(npz, FRAME_KIND)

    def __iter__(self):
        return (self[i] for i in range(len(self)))

    def calibration(self) -> list[CalibrationFrame]:
        """The calibration frames (chessboard described by ``manifest['calibration']['board']``)."""
        out = []
        for f in self.manifest["calibration"]["frames"]:
            image, truth = self._load(f["raw"], f.get("truth"), CALIB_KIND)
            out.append(CalibrationFrame(int(f["index"]), image, truth))
        return out

    def board(self):
        """The calibration target as a :class:`lipgen.recon.calibrate.Chessboard`."""
        from lipgen.rig.target import Chessboard

        b = self.manifest["calibration"]["board"]
        return Chessboard(b["inner_cols"], b["inner_rows"], b["square"])

    def calibration_boards(self) -> list:
        """Per calibration frame, its :class:`~lipgen.rig.target.Chessboard`: :meth:`board`, or the
        lens board (``manifest['calibration']['lens_board']``) for a frame whose entry says so."""
        from lipgen.rig.target import Chessboard

        cal = self.manifest["calibration"]
        out = []
        for f in cal["frames"]:
            b = cal[f["board"]] if "board" in f else cal["board"]
            out.append(Chessboard(b["inner_cols"], b["inner_rows"], b["square"]))
        return out


def save_annotated(ds: Dataset, index: int, out, tracked=None) -> Path:
    """Save a picture of raw frame ``index`` with the truth projections of the marks in both halves.

    Circles mark visible marks, crosses hidden ones (occluded, facing away or out of the view);
    each is labelled with its name. A dataset without truth (a recording) shows the frame alone.
    ``tracked (2, k, 2)``, optional: raw-frame pixels of tracked marks per view (NaN where lost),
    drawn as cyan plus signs. Written atomically (PNG, or any format matplotlib knows).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lipgen._io import atomic_savefig

    frame = ds[index]
    h, w = frame.image.shape[:2]
    fig = plt.figure(figsize=(w / 50, h / 50), dpi=100)
    ax = fig.add_axes((0, 0, 1, 0.94))
    ax.imshow(frame.image, interpolation="nearest")
    ax.axvline(ds.rig.split - 0.5, color="white", lw=0.8, ls="--")
    names = [str(n) for n in ds.marks]
    for v in range(len(VIEWS)) if frame.truth else ():
        uv, vis = frame.truth["uv_raw"][v], frame.truth["visible"][v]
        ax.scatter(uv[vis, 0], uv[vis, 1], s=60, facecolors="none", edgecolors="lime", linewidths=1.2)
        ax.scatter(uv[~vis, 0], uv[~vis, 1], s=50, marker="x", color="red", linewidths=1.2)
        for j, name in enumerate(names):
            ax.annotate(name, uv[j], xytext=(4, -4), textcoords="offset points", fontsize=5,
                        color="lime" if vis[j] else "red")
    if tracked is not None:
        t = np.asarray(tracked, dtype=float)
        if t.shape != (len(VIEWS), len(names), 2):
            raise ValueError(f"tracked must have shape ({len(VIEWS)}, {len(names)}, 2), got {t.shape}")
        for v in range(len(VIEWS)):
            ax.scatter(t[v, :, 0], t[v, :, 1], s=40, marker="+", color="cyan", linewidths=1.0)
            if not frame.truth:
                for j, name in enumerate(names):
                    if np.isfinite(t[v, j]).all():
                        ax.annotate(name, t[v, j], xytext=(4, -4), textcoords="offset points", fontsize=5,
                                    color="cyan")
    for label, cols in (("mirror (virtual view, flipped)", ds.rig.halves()[0]),
                        ("direct (real view)", ds.rig.halves()[1])):
        x0 = cols.start or 0
        ax.text(x0 + 4, 12, label, color="white", fontsize=7, va="top")
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)
    ax.axis("off")
    legend = "circles visible, crosses hidden" if frame.truth else "no ground truth"
    if tracked is not None:
        legend += "; plus signs tracked"
    fig.suptitle(f"{ds.path.name}  frame {frame.index}  t = {frame.time:.3f} s   (mirror half: "
                 f"{ds.rig.mirror_side}; {legend})", fontsize=9)
    out = Path(out)
    atomic_savefig(fig, out, dpi=100)
    plt.close(fig)
    return out
