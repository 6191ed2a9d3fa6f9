"""A dataset's manifest: its files' paths, what it records, and its checks (DESIGN.md's layout)."""

from __future__ import annotations

from pathlib import Path

from lipgen.dataset.checks import FORMAT, SCHEMA, _check_number, check_relative
from lipgen.dataset.settings import GenerateSettings
from lipgen.errors import DatasetError
from lipgen.rig.camera import VIEWS, MirrorRig

__all__ = ["TRUTH_FIELDS", "FRAME_KIND", "CALIB_KIND", "DEPTH_KIND", "build_manifest", "validate_manifest",
           "dataset_digest", "frame_paths", "calib_paths", "extra_paths", "mask_labels"]

FRAME_KIND, CALIB_KIND = "lipgen.dataset.frame", "lipgen.dataset.calibration"
DEPTH_KIND = "lipgen.dataset.depth"
"""Kind tags of the files a dataset holds: frame truth, calibration truth, depth."""

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


def dataset_digest(root) -> str:
    """SHA-256 (hex) of the dataset's ``manifest.json`` bytes: which dataset, wherever it lies
    (the manifest holds the settings, seed and version that determine its frames)."""
    import hashlib

    return hashlib.sha256((Path(root) / "manifest.json").read_bytes()).hexdigest()


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
    return extra | settings_entries(s, rig) | {
        "format": FORMAT, "lipgen_version": version, "units": "mm", "convention": "opencv",
        "pixels": "pixel (0, 0) is the centre of the top-left pixel; uv = (column, row)",
        "fps": s.fps, "views": list(VIEWS),
        "mesh": {"file": "mesh.npz", "name": mesh.name, "topology_id": mesh.topology_id,
                 "resolution": s.subject_resolution, "n_nodes": mesh.n_nodes, "n_faces": mesh.n_faces,
                 "marker_names": list(mesh.marker_names), "regions": list(mesh.region_names)},
        "marks": list(mesh.marker_names) + ["nose"], "actions": list(actions),
        "truth": {"kind": FRAME_KIND, "schema": SCHEMA, "fields": TRUTH_FIELDS},
    }


def settings_entries(s: GenerateSettings, rig: MirrorRig) -> dict:
    """The manifest entries that follow from the settings and the rig alone, without simulating
    the subject: schema version, seed, settings, rig, frames and calibration (a cached dataset is
    checked against them; :data:`lipgen.dataset.folder.SAME_DATASET_KEYS`)."""
    return {
        "schema_version": SCHEMA, "seed": s.seed, "settings": s.to_dict(), "rig": rig.to_dict(),
        "frames": [_frame_entry(s, i) for i in range(s.frames)],
        "calibration": {
            "board": {"type": "chessboard", "inner_cols": s.board[0], "inner_rows": s.board[1],
                      "square": s.board[2], "margin_squares": 2,
                      "frame": "origin at corner 0 (black outer diagonal square), x along a row of "
                               "corners, y along a column, z = x cross y; printed face is -z"},
            "pose_convention": "world X = A p + b for board points p",
            "truth": {"kind": CALIB_KIND, "schema": SCHEMA},
            "frames": [{"index": i, "raw": f"calib/{i:06d}.png", "truth": f"calib/{i:06d}.npz"}
                       | _lens_entry(s, i) for i in range(s.calib_frames)]} | _lens_board(s),
    }


def _lens_entry(s: GenerateSettings, i: int) -> dict:
    """A lens frame's manifest entry: the board it shows and the view it fills (else nothing)."""
    from lipgen.rig.target import lens_view

    k = i - (s.calib_frames - s.lens_frames)
    return {"board": "lens_board", "fills": lens_view(k)} if k >= 0 else {}


def _lens_board(s: GenerateSettings) -> dict:
    """The lens frames' board, when there are lens frames."""
    from lipgen.rig.target import LENS_BOARD

    if not s.lens_frames:
        return {}
    b = LENS_BOARD
    return {"lens_board": {"type": "chessboard", "inner_cols": b.inner_cols, "inner_rows": b.inner_rows,
                           "square": b.square, "margin_squares": 2,
                           "frames": "the last settings.lens_frames calibration frames (board: lens_board)"}}


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
        which = f.get("board", "board")
        if which not in ("board", "lens_board") or not isinstance(cal.get(which), dict):
            raise DatasetError(f"{where}: calibration.frames[{i}].board must name 'board' or 'lens_board' "
                               f"described in calibration; got {f.get('board')!r}")
    board = cal["board"]
    if not isinstance(board, dict) or not {"inner_cols", "inner_rows", "square"} <= set(board):
        raise DatasetError(f"{where}: calibration.board needs inner_cols, inner_rows, square")
