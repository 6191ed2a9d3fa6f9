"""Every class of bad input and the message it gets, run here and written to docs/bad_inputs.md.

The table is generated from these cases: if a message changes, this test fails until the doc is
regenerated with ``LIPGEN_UPDATE_DOCS=1 pytest tests/test_bad_inputs_table.py`` (or
``make bad-inputs``). Paths are shown relative to a scratch folder (``TMP/``).
"""

import os
from pathlib import Path

import numpy as np
import pytest

from lipgen.errors import LipgenError

DOC = Path(__file__).parents[1] / "docs" / "bad_inputs.md"
DOCUMENTED = (ValueError, TypeError, OSError, LipgenError)


def _lips():
    from lipgen.mesh.procedural import lip_mesh

    return lip_mesh(0)


def _manifest():
    from lipgen.dataset.layout import GenerateSettings, build_manifest
    from lipgen.rig.camera import default_rig

    s = GenerateSettings(frames=2, calib_frames=1, size=(160, 120))
    return build_manifest(s, default_rig(160, 120), _lips(), ["a"], "0")


def _edited(edit):
    from lipgen.dataset.layout import validate_manifest

    m = _manifest()
    edit(m)
    validate_manifest(m, "TMP/ds/manifest.json")


def _model(tmp: Path, key: str):
    from lipgen import Physics
    from lipgen.modes.model import ModeModel

    lips = _lips()
    rng = np.random.default_rng(0)
    ModeModel(3).fit_from_markers(Physics(lips), rng.normal(size=(8, 16, 3))).save(tmp / "model.npz")
    with np.load(tmp / "model.npz") as d:
        arrays = {k: d[k] for k in d.files}
    change = {"scaled": {"full_components": arrays["full_components"] * 1e6},
              "nan": {"total_variance": np.float64(np.nan)}}[key]
    np.savez(tmp / "model.npz", **{**arrays, **change})
    ModeModel.load(tmp / "model.npz")


def _tracks(tmp: Path, W):
    from lipgen.nrsfm import load_tracks

    np.savez(tmp / "tracks.npz", W=W)
    load_tracks(tmp / "tracks.npz")


def _nrsfm_option(tmp: Path, *opts):
    from lipgen.cli import build_parser
    from lipgen.commands import nrsfm

    np.savez(tmp / "tracks.npz", W=np.zeros((4, 5)))
    args = build_parser().parse_args(["nrsfm", str(tmp / "tracks.npz"), "--k", "auto", *opts,
                                      "--out", str(tmp / "s.npz")])
    nrsfm._run(args)


def _sidecar(tmp: Path, text: str):
    from lipgen.mesh.io import read_mesh, write_mesh

    write_mesh(_lips(), tmp / "lips.obj")
    (tmp / "lips.obj.json").write_text(text)
    read_mesh(tmp / "lips.obj")


def _cracked(tmp: Path):
    from lipgen.mesh.io import write_mesh
    from lipgen.mesh.lipmesh import LipMesh

    lips = _lips()
    V = np.vstack([lips.vertices, lips.vertices[:1]])
    F = lips.faces.copy()
    F[F == 0] = len(lips.vertices)  # every face of vertex 0 uses its copy; 0 keeps one face
    F[np.flatnonzero((lips.faces == 0).any(axis=1))[0]] = lips.faces[(lips.faces == 0).any(axis=1)][0]
    write_mesh(LipMesh(V, F, None, lips.anchors), tmp / "cracked.obj")
    LipMesh.from_file(tmp / "cracked.obj", anchors=lips.anchors)


def _usd_overflow(tmp: Path):
    pytest.importorskip("pxr")
    from lipgen.usd.export import export_usd

    lips = _lips()
    P = lips.vertices[None].copy()
    P[0, 0, 0] = 1e39
    export_usd(tmp / "lips.usda", lips, points=P)


def _empty_weights(tmp: Path):
    from lipgen.commands.export_usd import _load_array

    (tmp / "empty.npy").write_bytes(b"")
    _load_array(str(tmp / "empty.npy"), "weights", "weights")


def _out(tmp: Path, kind: str):
    from lipgen.commands._output import check_file_output, check_folder_output

    if kind == "exists":
        (tmp / "lips.usda").write_text("mine")
        check_file_output(tmp / "lips.usda", force=False)
    elif kind == "folder":
        check_file_output(tmp, force=False)
    elif kind == "missing":
        check_file_output(tmp / "nonexistent" / "r.npz", force=False)
    else:
        (tmp / "report").mkdir()
        (tmp / "report" / "report.md").write_text("mine")
        check_folder_output(tmp / "report", False, ("report.md", "report.json"))


def _reach_objective(tmp: Path):
    from lipgen import Physics, dofs

    lips = _lips()
    Physics(lips).reach(dofs(lips.markers[:2]), np.zeros(6), objective="strain")


def _cycles(tmp: Path, case: str):
    from test_renderer_choice import without_module

    from lipgen.dataset.generate import generate
    from lipgen.dataset.layout import GenerateSettings

    with without_module("bpy"):
        generate(tmp / "ds", GenerateSettings(frames=1, calib_frames=0, size=(160, 120), renderer="cycles"),
                 progress=False)


def _memory():
    from lipgen.dataset.footprint import check_motion_memory

    check_motion_memory(100000, 4, available=4 << 30)


def _frame(i: int, key: str, value):
    return lambda m: m["frames"][i].__setitem__(key, value)


CASES = [
    ("output", "`--out` names an existing file, no `--force`", lambda t: _out(t, "exists")),
    ("output", "`--out` is a folder where a file is expected", lambda t: _out(t, "folder")),
    ("output", "`--out` in a folder that does not exist", lambda t: _out(t, "missing")),
    ("output", "report folder already holds report.md", lambda t: _out(t, "report")),
    ("manifest", "frame path escaping the folder (`../../outside/x.png`)",
     lambda t: _edited(_frame(1, "raw", "../../outside/x.png"))),
    ("manifest", "absolute frame path (`/etc/passwd`)", lambda t: _edited(_frame(1, "raw", "/etc/passwd"))),
    ("manifest", "a frames entry that is a string",
     lambda t: _edited(lambda m: m["frames"].__setitem__(0, "x"))),
    ("manifest", "non-numeric fps", lambda t: _edited(lambda m: m.__setitem__("fps", "fast"))),
    ("manifest", "settings that are not an object",
     lambda t: _edited(lambda m: m.__setitem__("settings", [1]))),
    ("USD", "points beyond float32 (1e39)", _usd_overflow),
    ("USD", "`--weights` file that is empty", _empty_weights),
    ("model", "components not orthonormal (scaled by 1e6)",
     lambda t: _model(t, "scaled")),
    ("model", "total_variance NaN", lambda t: _model(t, "nan")),
    ("nrsfm", "W of one dimension", lambda t: _tracks(t, np.zeros(8))),
    ("nrsfm", "complex W", lambda t: _tracks(t, np.ones((4, 5), complex))),
    ("nrsfm", "boolean W", lambda t: _tracks(t, np.ones((4, 5), bool))),
    ("nrsfm", "`--kmax 0`", lambda t: _nrsfm_option(t, "--kmax", "0")),
    ("nrsfm", "`--rtol nan`", lambda t: _nrsfm_option(t, "--rtol", "nan")),
    ("mesh", "sidecar that is a JSON list", lambda t: _sidecar(t, "[1, 2]")),
    ("mesh", "a crack: a duplicated vertex used by faces", _cracked),
    ("physics", "unknown reach objective", _reach_objective),
    ("generate", "`--renderer cycles` without the pip `bpy`", lambda t: _cycles(t, "no bpy")),
    ("generate", "`--frames 100000 --subject-resolution 4` on a machine with 4 GB free", lambda t: _memory()),
    ("reconstruct", "`--rest model` with `--rest-from`", lambda t: _rest("model", "train.npz")),
    ("reconstruct", "`--rest recording` with 8 frames (6 training frames)", lambda t: _rest_frames(8)),
]


def _rest(rest, rest_from):
    from lipgen.recon.restsource import check_rest_options

    check_rest_options(rest, rest_from)


def _rest_frames(n):
    from lipgen.recon.restsource import rest_frames

    rest_frames(n)


def _run(case, tmp: Path) -> tuple[str, str]:
    try:
        case(tmp)
    except DOCUMENTED as exc:
        msg = str(exc).replace(str(tmp.resolve()), "TMP").replace(str(tmp), "TMP")
        assert "\n" not in msg.strip() and msg.strip(), msg
        return type(exc).__name__, msg
    raise AssertionError("no error raised")


def test_bad_inputs_table(tmp_path):
    rows = []
    for k, (group, what, case) in enumerate(CASES):
        folder = tmp_path / f"case{k}"
        folder.mkdir()
        name, msg = _run(case, folder)
        rows.append(f"| {group} | {what} | `{name}` | {msg.replace('|', chr(92) + '|')} |")
    text = ("# Bad inputs and their messages\n\n"
            "Generated by `tests/test_bad_inputs_table.py` (regenerate: `make bad-inputs`). Every row is "
            "run by the test suite; the CLI prints the message after `lipgen COMMAND: error:` and exits "
            "with 1. `TMP/` stands for the folder of the run.\n\n"
            "| input | bad input | error | message |\n|---|---|---|---|\n" + "\n".join(rows) + "\n")
    if os.environ.get("LIPGEN_UPDATE_DOCS"):
        DOC.write_text(text)
    assert DOC.is_file() and DOC.read_text() == text, (
        "docs/bad_inputs.md is out of date: run LIPGEN_UPDATE_DOCS=1 pytest tests/test_bad_inputs_table.py")
