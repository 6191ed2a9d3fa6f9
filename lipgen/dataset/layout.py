"""Synthetic camera-mirror datasets on disk: layout, manifest, settings and the reader.

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
from dataclasses import asdict, dataclass, fields
from functools import cached_property
from pathlib import Path

import numpy as np

from lipgen._io import load_npz
from lipgen.dataset.checks import FORMAT, SCHEMA, _check_number, check_relative, intact
from lipgen.errors import DatasetError, ModelFileError
from lipgen.rig.camera import VIEWS, MirrorRig
from lipgen.rig.conditions import ImageConditions

__all__ = ["Dataset", "DatasetFrame", "CalibrationFrame", "GenerateSettings", "TRUTH_FIELDS",
           "build_manifest", "validate_manifest", "frame_paths", "calib_paths", "extra_paths", "mask_labels",
           "check_relative", "intact"]

FRAME_KIND, CALIB_KIND = "lipgen.dataset.frame", "lipgen.dataset.calibration"
DEPTH_KIND = "lipgen.dataset.depth"

TRUTH_FIELDS: dict[str, str] = {
    "index": "frame number", "time": "seconds",
    "vertices": "(n, 3) subject vertices, model (head) frame, mm",
    "pose": "(4, 4) head pose, model -> world",
    "activations": "(A,) action activations, columns as manifest 'actions'",
    "mark_names": "(k,) the 16 marker names then 'nose'",
    "marks_model": "(k, 3) marks in the model frame, mm", "marks_world": "(k, 3) marks in the world, mm",
    "normals_world": "(k, 3) unit surface normals at the marks",
    "uv": "(2, k, 2) projections in the split views (virtual, real), px",
    "uv_raw": "(2, k, 2) the same in raw-frame pixels", "depth": "(2, k) view camera depth, mm",
    "in_image": "(2, k) inside the view", "occluded": "(2, k) line of sight blocked by a surface",
    "facing": "(2, k) the surface faces the view camera",
    "visible": "(2, k) in_image and not occluded and facing",
    "dot_visible_fraction": "(2, k) share of the ink dot's rim seen", "views": "(2,) view names",
    "uv_exposure": "(2, 2, k, 2) projections when the shutter opens and closes (only with motion blur)",
}
"""The arrays of a frame's truth file, with their shapes and units."""
_REQUIRED = ("format", "schema_version", "units", "convention", "seed", "settings", "rig", "views", "mesh",
             "marks", "actions", "frames", "calibration", "lipgen_version")


@dataclass(frozen=True)
class GenerateSettings:
    """Everything that determines a dataset's bytes (with the lipgen version)."""

    frames: int = 150
    seed: int = 0
    script: str | None = None
    """Viseme script (repeated to fill the frames); smooth random activations if None."""
    size: tuple[int, int] = (640, 480)
    fps: float = 30.0
    subject_resolution: int = 1
    head_rotation_deg: float = 4.0
    head_translation_mm: float = 4.0
    noise: float = 1.0
    """Sensor noise, standard deviation in 8-bit grey levels."""
    dot_diameter: float = 2.0
    calib_frames: int = 10
    board: tuple[int, int, float] = (9, 6, 8.0)
    """Chessboard inner corners (cols, rows) and square size, mm."""
    png_compress_level: int = 1
    depth: bool = False
    """Also write each raw frame's depth (``depth/NNNNNN.npz``: view-camera z in mm, NaN off the face)."""
    masks: bool = False
    """Also write each raw frame's label mask (``masks/NNNNNN.png``: ids in ``manifest['mask_labels']``)."""
    speech: str | None = None
    """A speech recording (WAV) whose phones time the motion (:mod:`lipgen.speech`)."""
    speech_text: str | None = None
    """The transcript of ``speech``, or, alone, English text spoken with Klatt-rule durations."""
    subject_seed: int | None = None
    """Draws the subject's own lip shape and ink-dot placement (:mod:`lipgen.subject.shape`); None:
    the model's shape with the dots on its marker nodes (the data before subject seeds existed)."""
    truth_physics: str = "linear"
    """``"linear"`` (the linear truth subject) or ``"layer"`` (the nonlinear tissue layer,
    :mod:`lipgen.subject.layer`; seconds per frame)."""
    preset: str | None = None
    """The preset these settings came from (:mod:`lipgen.dataset.presets`), recorded as such;
    None is ``easy`` (the data before presets, whose manifests name none)."""

    conditions: ImageConditions = ImageConditions()
    """Lens, mirror, light and sensor (:mod:`lipgen.rig.conditions`); the default is the ideal camera."""

    @classmethod
    def from_preset(cls, name: str, **overrides) -> GenerateSettings:
        """Settings of preset ``name`` (``easy``, ``default``, ``hard``), any field overridden by
        ``overrides`` (those that are not None)."""
        from lipgen.dataset.presets import get_preset

        p = get_preset(name)
        base = {"head_rotation_deg": p.motion.head_rotation_deg,
                "head_translation_mm": p.motion.head_translation_mm, "noise": p.image.noise,
                "dot_diameter": p.image.dot_diameter, "conditions": p.image.conditions,
                "truth_physics": "layer" if p.subject.nonlinear_physics else "linear",
                "subject_seed": p.subject.default_subject_seed if p.subject.own_shape else None}
        given = {k: v for k, v in overrides.items() if v is not None}
        if not p.subject.own_shape and given.get("subject_seed") is not None:
            raise ValueError(f"preset {name!r} films the model's own shape; a subject seed needs preset "
                             "'default' or 'hard'")
        # easy is the data before presets, byte for byte: its manifest names no preset
        return cls(**{**base, **given, "preset": None if p.name == "easy" else p.name})

    def __post_init__(self) -> None:
        def whole(name, lo, hi):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or not lo <= v <= hi:
                raise ValueError(f"{name} must be a whole number in [{lo}, {hi}], got {v!r}")

        whole("frames", 1, 10**6)
        whole("seed", 0, 2**63 - 1)
        whole("subject_resolution", 1, 4)
        whole("calib_frames", 0, 1000)
        whole("png_compress_level", 0, 9)
        if self.subject_seed is not None:
            from lipgen.subject.shape import MAX_SUBJECT_SEED

            whole("subject_seed", 0, MAX_SUBJECT_SEED)
        if self.truth_physics not in ("linear", "layer"):
            raise ValueError(f"truth_physics must be 'linear' or 'layer', got {self.truth_physics!r}")
        if self.preset is not None:
            from lipgen.dataset.presets import get_preset

            get_preset(self.preset)
        w, h = (int(x) for x in self.size)
        if w < 16 or h < 12 or w * 3 != h * 4:
            raise ValueError(f"size must be W x H with a 4:3 aspect (the default rig), e.g. 640x480; "
                             f"got {w}x{h}")
        object.__setattr__(self, "size", (w, h))
        for name, lo, hi in (("fps", 1, 1000), ("head_rotation_deg", 0, 30), ("head_translation_mm", 0, 50),
                             ("noise", 0, 50), ("dot_diameter", 0.2, 10)):
            v = float(getattr(self, name))
            if not lo <= v <= hi:
                raise ValueError(f"{name} must be in [{lo}, {hi}], got {v}")
            object.__setattr__(self, name, v)
        if self.script is not None and (self.speech or self.speech_text):
            raise ValueError("choose one source of motion: a viseme script or speech, not both")
        if self.script is not None:
            from lipgen.subject.motion import parse_script

            parse_script(self.script)  # unknown visemes: a clear error now, not after the simulation
        for name in ("depth", "masks"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be True or False, got {getattr(self, name)!r}")
        c, r, sq = self.board
        object.__setattr__(self, "board", (int(c), int(r), float(sq)))
        if isinstance(self.conditions, dict):  # as to_dict() writes it
            object.__setattr__(self, "conditions", ImageConditions.from_dict(self.conditions))
        if not isinstance(self.conditions, ImageConditions):
            raise TypeError(f"conditions must be ImageConditions, got {type(self.conditions).__name__}")

    def to_dict(self) -> dict:
        """The settings as a JSON-ready dict (as stored in the manifest)."""
        d = asdict(self)
        d["size"], d["board"] = list(self.size), list(self.board)
        for key in ("speech", "speech_text"):  # absent, as in manifests written before they existed
            if d[key] is None:
                del d[key]
        for k, unset in (("subject_seed", None), ("truth_physics", "linear"), ("preset", None)):
            if d[k] == unset:  # unset: the manifest of such data is as it always was
                del d[k]
        d["conditions"] = self.conditions.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: dict) -> GenerateSettings:
        """Settings from a manifest's dict, checking every key and value."""
        if not isinstance(d, dict):
            raise ValueError(f"generator settings must be a JSON object, got {type(d).__name__}")
        known = {f.name for f in fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"unknown generator settings {sorted(unknown)}")
        return cls(**{k: tuple(v) if k in ("size", "board") else v for k, v in d.items()})


def frame_paths(root, i: int) -> tuple[Path, Path]:
    """(raw PNG, truth npz) of frame ``i``."""
    return Path(root) / "raw" / f"{i:06d}.png", Path(root) / "truth" / f"{i:06d}.npz"


def calib_paths(root, i: int) -> tuple[Path, Path]:
    """(PNG, truth npz) of calibration frame ``i``."""
    return Path(root) / "calib" / f"{i:06d}.png", Path(root) / "calib" / f"{i:06d}.npz"


def extra_paths(root, i: int) -> tuple[Path, Path]:
    """(depth npz, mask PNG) of frame ``i``, written when the settings ask for them."""
    return Path(root) / "depth" / f"{i:06d}.npz", Path(root) / "masks" / f"{i:06d}.png"


def _frame_entry(s: GenerateSettings, i: int) -> dict:
    entry = {"index": i, "time": i / s.fps, "raw": f"raw/{i:06d}.png", "truth": f"truth/{i:06d}.npz"}
    if s.depth:
        entry["depth"] = f"depth/{i:06d}.npz"
    if s.masks:
        entry["mask"] = f"masks/{i:06d}.png"
    return entry


def mask_labels(mesh) -> dict[str, str]:
    """Label id (as a string, for JSON) -> name, for the masks of a dataset of ``mesh``."""
    from lipgen.subject.face import DOT_LABEL0, LABELS

    labels = {str(k): v for k, v in LABELS.items()}
    labels.update({str(DOT_LABEL0 + k): f"dot:{n}" for k, n in enumerate([*mesh.marker_names, "nose"])})
    return labels


def build_manifest(s: GenerateSettings, rig: MirrorRig, mesh, actions: list[str], version: str,
                   subject: dict | None = None) -> dict:
    """The manifest of a dataset made with settings ``s`` (deterministic: no clock, no paths).

    ``subject`` (the subject seed, shape parameters and ink-dot surface points) is recorded
    under ``"subject"`` when given."""
    extra = {"mask_labels": mask_labels(mesh)} if s.masks else {}
    if subject is not None:
        extra["subject"] = subject
    return extra | {
        "format": FORMAT, "schema_version": SCHEMA, "lipgen_version": version, "units": "mm",
        "convention": "opencv",
        "pixels": "pixel (0, 0) is the centre of the top-left pixel; uv = (column, row)",
        "seed": s.seed, "fps": s.fps, "settings": s.to_dict(), "rig": rig.to_dict(), "views": list(VIEWS),
        "mesh": {"file": "mesh.npz", "name": mesh.name, "topology_id": mesh.topology_id,
                 "resolution": s.subject_resolution, "n_nodes": mesh.n_nodes, "n_faces": mesh.n_faces,
                 "marker_names": list(mesh.marker_names), "regions": list(mesh.region_names)},
        "marks": list(mesh.marker_names) + ["nose"], "actions": list(actions),
        "frames": [_frame_entry(s, i) for i in range(s.frames)],
        "truth": {"kind": FRAME_KIND, "schema": SCHEMA, "fields": TRUTH_FIELDS},
        "calibration": {
            "board": {"type": "chessboard", "inner_cols": s.board[0], "inner_rows": s.board[1],
                      "square": s.board[2], "margin_squares": 2,
                      "frame": "origin at corner 0 (black outer diagonal square), x along a row of "
                               "corners, y along a column, z = x cross y; printed face is -z"},
            "pose_convention": "world X = A p + b for board points p",
            "truth": {"kind": CALIB_KIND, "schema": SCHEMA},
            "frames": [{"index": i, "raw": f"calib/{i:06d}.png", "truth": f"calib/{i:06d}.npz"}
                       for i in range(s.calib_frames)]},
    }


def validate_manifest(m, where="manifest") -> None:
    """Raise :class:`DatasetError` unless ``m`` is a well-formed manifest this lipgen reads.

    Every file it names must be a relative path inside the dataset folder (:func:`check_relative`).
    """
    try:
        _validate_manifest(m, where)
    except (TypeError, AttributeError, KeyError, IndexError) as exc:  # a field of the wrong type
        raise DatasetError(f"{where}: malformed manifest ({type(exc).__name__}: {exc})") from exc


def _validate_manifest(m, where) -> None:
    if not isinstance(m, dict):
        raise DatasetError(f"{where}: a manifest is a JSON object, got {type(m).__name__}")
    missing = [k for k in _REQUIRED if k not in m]
    if missing:
        raise DatasetError(f"{where} lacks {missing}; it is not a complete lipgen dataset manifest")
    if m["format"] != FORMAT:
        raise DatasetError(f"{where}: format is {m['format']!r}, not {FORMAT!r}")
    if m["schema_version"] != SCHEMA:
        raise DatasetError(f"{where}: schema version {m['schema_version']}; this lipgen reads {SCHEMA}. "
                           "Regenerate the dataset with this lipgen")
    if m["units"] != "mm" or m["convention"] != "opencv" or list(m["views"]) != list(VIEWS):
        raise DatasetError(f"{where}: expected units 'mm', convention 'opencv', views {list(VIEWS)}")
    recording = m.get("source") == "recording"
    try:
        if recording:
            from lipgen.dataset.footage import RecordingSettings

            RecordingSettings.from_dict(m["settings"])
        else:
            GenerateSettings.from_dict(m["settings"])
        MirrorRig.from_dict(m["rig"])
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise DatasetError(f"{where}: bad settings or rig: {exc}") from exc
    n = m["settings"]["frames"]
    frames = m["frames"]
    if not isinstance(frames, list) or len(frames) != n:
        got = f"a list of {len(frames)}" if isinstance(frames, list) else type(frames).__name__
        raise DatasetError(f"{where}: the frame list must have {n} entries (settings.frames), got {got}")
    for i, f in enumerate(frames):
        if not isinstance(f, dict) or f.get("index") != i or "raw" not in f:
            raise DatasetError(f"{where}: frames[{i}] must be an object with index {i}, raw and (optional) "
                               f"truth; got {str(f)[:80]!r}")
        _check_number(f.get("time", 0.0), f"{where}: frames[{i}].time")
        for key in ("raw", "truth", "depth", "mask"):
            if key in f:
                check_relative(f[key], f"{where}: frames[{i}].{key}")
    _check_number(m.get("fps", 1.0), f"{where}: fps", positive=True)
    mesh = m["mesh"]
    if not isinstance(mesh, dict) or not {"file", "topology_id", "resolution", "n_nodes"} <= set(mesh):
        raise DatasetError(f"{where}: mesh needs file, topology_id, resolution, n_nodes; got "
                           f"{sorted(mesh) if isinstance(mesh, dict) else type(mesh).__name__}")
    check_relative(mesh["file"], f"{where}: mesh.file")
    marks, names = m["marks"], mesh.get("marker_names", [])
    if (not isinstance(marks, list) or not isinstance(names, list) or len(marks) != len(names) + 1
            or marks[-1:] != ["nose"]):
        raise DatasetError(f"{where}: marks must be the marker names then 'nose'")
    cal = m["calibration"]
    n_cal = m["settings"]["calib_frames"]
    if (not isinstance(cal, dict) or not {"board", "frames"} <= set(cal)
            or not isinstance(cal["frames"], list) or len(cal["frames"]) != n_cal):
        raise DatasetError(f"{where}: calibration needs the board and {n_cal} frames")
    for i, f in enumerate(cal["frames"]):
        if not isinstance(f, dict) or "raw" not in f or not isinstance(f.get("index"), int):
            raise DatasetError(f"{where}: calibration.frames[{i}] must be an object with index, raw and "
                               f"(optional) truth; got {str(f)[:80]!r}")
        for key in ("raw", "truth"):
            if key in f:
                check_relative(f[key], f"{where}: calibration.frames[{i}].{key}")
    board = cal["board"]
    if not isinstance(board, dict) or not {"inner_cols", "inner_rows", "square"} <= set(board):
        raise DatasetError(f"{where}: calibration.board needs inner_cols, inner_rows, square")


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
                "compares with the truth, so it needs a synthetic dataset from lipgen generate. "
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
        if npz is None:
            return image, {}
        try:
            truth = load_npz(npz, kind, SCHEMA)
        except ModelFileError as exc:
            raise DatasetError(f"{exc}; redo it with lipgen generate --resume (same settings)") from exc
        return image, truth

    def __getitem__(self, i: int) -> DatasetFrame:
        n = len(self)
        if isinstance(i, bool) or not isinstance(i, int | np.integer) or not -n <= i < n:
            raise IndexError(f"frame {i!r} is out of range for a dataset of {n} frames")
        f = self.manifest["frames"][int(i) % n]
        image, truth = self._load(f["raw"], f.get("truth"), FRAME_KIND)
        return DatasetFrame(int(f["index"]), float(f["time"]), image, truth)

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

    from lipgen._io import atomic_path

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
    with atomic_path(out) as tmp:
        fig.savefig(tmp, dpi=100, format=(out.suffix.lstrip(".") or "png"))
    plt.close(fig)
    return out

