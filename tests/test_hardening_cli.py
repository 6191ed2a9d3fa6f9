"""Hardening of the command line and the file formats (issue 20): --force everywhere, output
paths checked before the work, killed writers leave nothing behind, float32 overflow and
inconsistent files refused, one-line errors instead of tracebacks."""

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lipgen import Physics, dofs
from lipgen._io import atomic_path, stale_temporaries
from lipgen.cli import main
from lipgen.errors import MeshError, ModelFileError
from lipgen.mesh.procedural import lip_mesh
from lipgen.modes.model import ModeModel

DEAD = 2**22 + 4321  # above Linux's default pid_max: never a running process


@pytest.fixture(scope="module")
def mesh():
    return lip_mesh(0)


@pytest.fixture(scope="module")
def fitted(mesh):
    rng = np.random.default_rng(1)
    physics = Physics(mesh)
    model = ModeModel(n_modes=4).fit_from_markers(physics, rng.normal(scale=2.0, size=(20, 16, 3)))
    fields, _ = physics.reach(dofs(mesh.markers), rng.normal(scale=2.0, size=(6, 48)))
    return model, model.project(fields)


@pytest.fixture()
def files(tmp_path, mesh, fitted):
    model, weights = fitted
    mesh.save(tmp_path / "mesh.npz")
    model.save(tmp_path / "model.npz")
    np.save(tmp_path / "w.npy", weights)
    return tmp_path


def _err(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err


# ---- outputs: --force, folders, missing parents --------------------------------------------

@pytest.mark.parametrize("argv", [
    ["export-usd", "--model", "{d}/model.npz", "--mesh", "{d}/mesh.npz", "--out", "{out}"],
    ["show", "{d}/no_dataset", "--out", "{out}"],
    ["reconstruct", "{d}/no_dataset", "--out", "{out}"],
    ["train", "{d}/recon.npz", "--out", "{out}"],
    ["nrsfm", "{d}/t.npz", "--k", "2", "--out", "{out}"],
    ["bench", "--suite", "none", "--out", "{out}"],
    ["mesh", "--out", "{out}"],
])
def test_every_writing_command_keeps_an_existing_file(files, capsys, argv):
    suffix = {"export-usd": ".usda", "mesh": ".obj"}.get(argv[0], ".npz")
    out = files / f"keep{suffix}"
    out.write_bytes(b"the user's file")
    code = main([a.format(d=files, out=out) for a in argv])
    assert code == 1 and "--force" in _err(capsys)
    assert out.read_bytes() == b"the user's file"


@pytest.mark.parametrize("cmd", [["reconstruct", "ds"], ["train", "r.npz"], ["nrsfm", "t.npz", "--k", "2"],
                                 ["bench"], ["show", "ds"]])
def test_output_in_a_missing_folder_fails_first_and_creates_nothing(tmp_path, capsys, cmd):
    out = tmp_path / "nonexistent" / "deeper" / "r.npz"
    assert main([*cmd, "--out", str(out)]) == 1
    err = _err(capsys)
    assert "does not exist" in err and str(out.parent) in err
    assert not (tmp_path / "nonexistent").exists()


def test_a_folder_as_out_is_named_not_a_temporary_file(files, capsys):
    assert main(["export-usd", "--model", str(files / "model.npz"), "--mesh", str(files / "mesh.npz"),
                 "--out", str(files)]) == 1
    err = _err(capsys)
    assert "is a folder" in err and ".tmp-" not in err
    with pytest.raises(IsADirectoryError, match="is a folder"):
        with atomic_path(files):
            pass


def test_evaluate_refuses_to_replace_a_report_and_checks_the_folder_first(files, capsys, monkeypatch):
    report = files / "report"
    report.mkdir()
    (report / "report.md").write_text("my notes")
    argv = ["evaluate", str(files / "no_dataset"), "--model", str(files / "model.npz"), "--out", str(report)]
    assert main(argv) == 1
    assert "report.md" in _err(capsys) and (report / "report.md").read_text() == "my notes"
    import lipgen.commands._output as output

    ro = files / "readonly"
    ro.mkdir()
    monkeypatch.setattr(output.os, "access", lambda p, mode: Path(p) != ro)  # root writes anywhere
    assert main(["evaluate", "x", "--model", "m.npz", "--out", str(ro)]) == 1
    assert "not writable" in _err(capsys)


def test_bench_out_refused_without_creating_folders(tmp_path, capsys):
    assert main(["bench", "--out", str(tmp_path / "a" / "b.json")]) == 1
    assert "does not exist" in _err(capsys) and not (tmp_path / "a").exists()


# ---- temporaries of killed writers ---------------------------------------------------------

_SLOW_EXPORT = """
import sys, time
import numpy as np
import lipgen.usd.export as ex
from lipgen.mesh.procedural import lip_mesh
real = ex._write_layer
def slow(layer, tmp, ext, stem):
    real(layer, tmp, ext, stem)
    print("written", flush=True)
    time.sleep(60)
ex._write_layer = slow
ex.export_usd(sys.argv[1], lip_mesh(0), points=lip_mesh(0).vertices[None] + np.zeros((3, 1, 3)))
"""


@pytest.mark.usd
@pytest.mark.parametrize("ext", [".usda", ".usdz"])
def test_a_killed_export_leaves_temporaries_the_next_export_removes(tmp_path, mesh, ext):
    pytest.importorskip("pxr")
    from lipgen.usd.export import export_usd

    dest = tmp_path / f"lips{ext}"
    proc = subprocess.Popen([sys.executable, "-c", _SLOW_EXPORT, str(dest)], stdout=subprocess.PIPE,
                            env={**os.environ, "PYTHONPATH": str(Path(__file__).parents[1])})
    line = proc.stdout.readline()
    assert line.strip() == b"written"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    left = [p for p in tmp_path.iterdir() if p.name.startswith(f".{dest.name}.tmp-")]
    assert left and not dest.exists()  # the kill left its temporary file(s)
    assert sorted(stale_temporaries(dest)) == sorted(left)
    export_usd(dest, mesh)
    assert sorted(p.name for p in tmp_path.iterdir()) == [dest.name]


def test_only_a_dead_writers_temporaries_are_removed(tmp_path):
    dest = tmp_path / "x.json"
    mine = tmp_path / ".x.json.tmp-mybackup"
    live = tmp_path / f".x.json.tmp-{os.getpid()}-abc.json"
    dead = tmp_path / f".x.json.tmp-{DEAD}-abc.json"
    for p in (mine, live, dead):
        p.write_text("x")
    with atomic_path(dest) as tmp:
        tmp.write_text("{}")
    assert mine.exists() and live.exists() and not dead.exists() and dest.read_text() == "{}"


# ---- silent garbage ------------------------------------------------------------------------

@pytest.mark.usd
def test_float32_overflow_is_refused_and_validate_catches_non_finite(files, mesh, fitted, capsys):
    pytest.importorskip("pxr")
    from lipgen.usd.export import export_usd, validate

    model, weights = fitted
    big = mesh.vertices[None].copy()
    big[0, 3, 0] = 1e39
    with pytest.raises(ValueError, match="float32"):
        export_usd(files / "a.usda", mesh, points=big)
    with pytest.raises(ValueError, match="float32"):
        export_usd(files / "b.usda", mesh, model, weights * 1e39)
    np.save(files / "p.npy", big)
    assert main(["export-usd", "--points", str(files / "p.npy"), "--mesh", str(files / "mesh.npz"),
                 "--out", str(files / "c.usda")]) == 1
    assert "float32" in _err(capsys)
    assert not any(files.glob("*.usda"))
    path = export_usd(files / "d.usda", mesh, points=mesh.vertices[None] + np.zeros((2, 1, 3)))
    from pxr import Usd, UsdGeom, Vt

    stage = Usd.Stage.Open(str(path))
    prim = next(p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh))
    attr = UsdGeom.Mesh(prim).GetPointsAttr()
    t = attr.GetTimeSamples()[1]
    pts = np.array(attr.Get(t), dtype=np.float32)
    pts[0, 0] = np.inf
    attr.Set(Vt.Vec3fArray.FromNumpy(pts), t)
    stage.GetRootLayer().Save()
    errors = [i for i in validate(path) if i.is_error]
    assert any(i.name == "NonFiniteValues" for i in errors), errors
    (files / "e.usda").write_text("#usda 1.0\n(garbage")
    with pytest.raises(ValueError, match="e.usda is not a readable USD file"):
        validate(files / "e.usda")


def test_mode_model_load_refuses_inconsistent_files(tmp_path, fitted):
    model, _ = fitted
    model.save(tmp_path / "m.npz")
    with np.load(tmp_path / "m.npz") as d:
        arrays = {k: d[k] for k in d.files}
    for change, match in (({"full_components": arrays["full_components"] * 1e6}, "not orthonormal"),
                          ({"total_variance": np.float64(np.nan)}, "total_variance"),
                          ({"total_variance": np.float64(-1.0)}, "total_variance")):
        np.savez(tmp_path / "bad.npz", **{**arrays, **change})
        with pytest.raises(ModelFileError, match=match):
            ModeModel.load(tmp_path / "bad.npz")
    assert ModeModel.load(tmp_path / "m.npz").total_variance_ == model.total_variance_


@pytest.mark.parametrize("W,match", [
    (np.zeros(8), "2F x P"), (np.zeros((3, 4)), "2F x P"), (np.ones((4, 5), complex), "complex"),
    (np.ones((4, 5), bool), "real numbers")])
def test_nrsfm_refuses_bad_tracks(tmp_path, capsys, W, match):
    np.savez(tmp_path / "t.npz", W=W)
    assert main(["nrsfm", str(tmp_path / "t.npz"), "--k", "1", "--out", str(tmp_path / "s.npz")]) == 1
    assert match in _err(capsys) and not (tmp_path / "s.npz").exists()


@pytest.mark.parametrize("opts,match", [(["--kmax", "0"], "--kmax"), (["--rtol", "nan"], "--rtol"),
                                        (["--rtol", "-1"], "--rtol"), (["--rtol", "1.5"], "--rtol")])
def test_nrsfm_refuses_bad_options(tmp_path, capsys, opts, match):
    np.savez(tmp_path / "t.npz", W=np.random.default_rng(0).normal(size=(20, 12)))
    argv = ["nrsfm", str(tmp_path / "t.npz"), "--k", "auto", *opts, "--out", str(tmp_path / "s.npz")]
    assert main(argv) == 1
    assert match in _err(capsys)


def test_reconstruction_paths_are_relative_to_the_file(tmp_path, monkeypatch):
    from lipgen.recon.pipeline import _paths_relative_to, _paths_resolved_from

    info = {"dataset": str(tmp_path / "data" / "s0"), "mesh_source": str(tmp_path / "meshes" / "m.npz")}
    on_disk = _paths_relative_to(info, tmp_path / "out" / "recon.npz")
    assert on_disk == {"dataset": "../data/s0", "mesh_source": "../meshes/m.npz"}
    assert _paths_resolved_from(on_disk, tmp_path / "out" / "recon.npz") == info
    assert _paths_relative_to({"mesh_source": "lip_mesh(0)"}, "r.npz") == {"mesh_source": "lip_mesh(0)"}


# ---- one-line errors -----------------------------------------------------------------------

def test_empty_weights_file_is_one_line(files, capsys):
    (files / "empty.npy").write_bytes(b"")
    assert main(["export-usd", "--model", str(files / "model.npz"), "--mesh", str(files / "mesh.npz"),
                 "--weights", str(files / "empty.npy"), "--out", str(files / "x.usda")]) == 1
    err = _err(capsys)
    assert "empty.npy" in err and "empty, truncated" in err


def test_a_sidecar_that_is_not_an_object_is_a_mesh_error(tmp_path, capsys, mesh):
    from lipgen.mesh.io import read_mesh, write_mesh

    write_mesh(mesh, tmp_path / "m.obj")
    for text in ("[1, 2]", '"x"', "3", '{"kind": "lipgen.LipMesh.sidecar", "schema": 1, "markers": 5}'):
        (tmp_path / "m.obj.json").write_text(text)
        with pytest.raises(MeshError, match="m.obj.json"):
            read_mesh(tmp_path / "m.obj")
        assert main(["mesh", "--from", str(tmp_path / "m.obj")]) == 1
        assert "m.obj.json" in _err(capsys)


def test_blender_extension_missing_source_is_named(tmp_path, capsys):
    assert main(["blender-extension", "--out", str(tmp_path / "dist"), "--source", str(tmp_path / "missing"),
                 "--offline"]) == 1
    err = _err(capsys)
    assert str(tmp_path / "missing") in err and "blender_manifest.toml" in err and "lipgen-ext" not in err


def test_wheel_lists_what_ships(tmp_path):
    import shutil

    from lipgen.blender.packaging import shipped_files

    pkg = tmp_path / "lipgen"
    shutil.copytree(Path(__file__).parents[1] / "lipgen", pkg, ignore=shutil.ignore_patterns("__pycache__"))
    (pkg / "notes.txt").write_text("private")
    (pkg / "mesh" / ".lips.npz.tmp-1-x.npz").write_text("temporary")
    (pkg / "stray").mkdir()
    (pkg / "stray" / "x.py").write_text("")
    names = {p.relative_to(pkg).as_posix() for p in shipped_files(pkg)}
    assert "__init__.py" in names and "mesh/io.py" in names
    assert not {"notes.txt", "stray/x.py", "mesh/.lips.npz.tmp-1-x.npz"} & names
    assert all(n.endswith(".py") for n in names)


def test_no_developer_path_ships(tmp_path):
    root = Path(__file__).parents[1] / "lipgen"
    hits = [p for p in root.rglob("*.py") if "/work/" in p.read_text()]
    assert not hits, hits
    from lipgen.experiments.nrsfm_benchmarks import data_dir

    env = os.environ.get("LIPGEN_NRSFM_DATA")
    inside = root.parent / "benchmarks" / "nrsfm"
    beside = root.parent.parent / "shared" / "benchmarks" / "nrsfm"
    want = beside if not inside.is_dir() and beside.is_dir() else inside
    assert data_dir() == (Path(env) if env else want)


def test_blender_extension_keeps_an_existing_zip(tmp_path, capsys):
    import tomllib

    meta = tomllib.loads((Path(__file__).parents[1] / "blender_addon" / "blender_manifest.toml").read_text())
    out = tmp_path / "dist"
    out.mkdir()
    mine = out / f"{meta['id']}-{meta['version']}-linux_x64.zip"
    mine.write_bytes(b"my build")
    assert main(["blender-extension", "--out", str(out), "--platform", "linux-x64", "--offline"]) == 1
    assert "--force" in _err(capsys) and mine.read_bytes() == b"my build"
