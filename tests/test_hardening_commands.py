"""Bad inputs and outputs of the commands, refused before the work (audit harden20): --force never
replaces an input, every report file needs --force, no folders made on the way, sizes the machine
cannot hold named in one line."""

import argparse
from pathlib import Path

import pytest

from lipgen.cli import main


def _err(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err


def _tree(root: Path) -> dict:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture()
def ds(tmp_path):
    """A folder that looks like a dataset to the output checks (they run before it is read)."""
    d = tmp_path / "ds"
    (d / "raw").mkdir(parents=True)
    (d / "manifest.json").write_text("{}")
    (d / "mesh.npz").write_bytes(b"the dataset's mesh")
    (d / "raw" / "000000.png").write_bytes(b"frame 0")
    return d


# ---- --force replaces outputs, never an input --------------------------------------------

@pytest.mark.parametrize("argv", [
    ["train", "{t}/r.npz", "--out", "{t}/r.npz"],                               # its own input file
    ["show", "{d}", "--out", "{d}/raw/000000.png"],                             # a frame of the dataset
    ["reconstruct", "{d}", "--out", "{d}/mesh.npz"],                            # the dataset's mesh
    ["reconstruct", "{d}", "--rest-from", "{t}/r.npz", "--out", "{t}/r.npz"],
    ["evaluate", "{d}", "--model", "{t}/rep/recon.npz", "--out", "{t}/rep"],   # writes rep/recon.npz
    ["show", "{d}", "--out", "{t}/link.png"],                                   # a symlink into the dataset
    ["lipsync", "--text", "hello", "--model", "{t}/r.npz", "--out", "{t}/r.npz"],
    ["nrsfm", "{t}/r.npz", "--k", "2", "--out", "{t}/r.npz"],
])
def test_force_never_replaces_an_input(tmp_path, ds, capsys, argv):
    (tmp_path / "r.npz").write_bytes(b"the user's reconstruction")
    (tmp_path / "rep").mkdir()
    (tmp_path / "rep" / "recon.npz").write_bytes(b"the user's model")
    (tmp_path / "link.png").symlink_to(ds / "raw" / "000000.png")
    before = _tree(tmp_path)
    assert main([a.format(t=tmp_path, d=ds) for a in argv] + ["--force"]) == 1
    err = _err(capsys)
    assert "input" in err and "even with --force" in err
    assert _tree(tmp_path) == before


def test_evaluate_keeps_every_report_file_without_force(tmp_path, capsys):
    from lipgen.evaluate.report import REPORT_FILES

    report = tmp_path / "report"
    report.mkdir()
    (report / "frame.png").write_bytes(b"my picture")
    assert "frame.png" in REPORT_FILES and "modes.png" in REPORT_FILES
    assert main(["evaluate", str(tmp_path / "no_dataset"), "--model", "m.npz", "--out", str(report)]) == 1
    assert "frame.png" in _err(capsys) and (report / "frame.png").read_bytes() == b"my picture"


# ---- lipgen recording init: --out never overlaps its inputs; --force replaces a recording only

def _recording(tmp_path, out, force=True):
    from lipgen.recon.recording import init_recording

    init_recording(tmp_path / "frames", tmp_path / "boards", out, force=force)


@pytest.mark.parametrize("case", ["the photos", "holds the footage", "foreign folder", "missing parent"])
def test_recording_out_is_checked_before_anything_is_replaced(tmp_path, case):
    for name in ("frames", "boards", "mine"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "a.png").write_bytes(name.encode())
    before = _tree(tmp_path)
    out, error, match = {
        "the photos": (tmp_path / "boards", ValueError, "overlaps --calib"),
        "holds the footage": (tmp_path, ValueError, "overlaps the footage"),
        "foreign folder": (tmp_path / "mine", FileExistsError, "holds other files"),
        "missing parent": (tmp_path / "no" / "rec", FileNotFoundError, "does not exist"),
    }[case]
    with pytest.raises(error, match=match):
        _recording(tmp_path, out)
    assert _tree(tmp_path) == before and not (tmp_path / "no").exists()


# ---- generate: no folders made on the way; sizes it cannot render ------------------------

def test_generate_refuses_a_missing_parent_before_the_physics(tmp_path, capsys):
    out = tmp_path / "missing" / "deeper" / "ds"
    assert main(["generate", "--frames", "2", "--size", "160x120", "--calib-frames", "1", "--no-progress",
                 "--out", str(out)]) == 1
    assert "does not exist" in _err(capsys) and not (tmp_path / "missing").exists()


def test_generate_refuses_a_size_the_renderer_cannot_draw(tmp_path, capsys):
    from lipgen.dataset.layout import GenerateSettings
    from lipgen.dataset.settings import MAX_WIDTH

    GenerateSettings(size=(MAX_WIDTH, MAX_WIDTH * 3 // 4))
    assert main(["generate", "--frames", "2", "--size", "16000x12000", "--out", str(tmp_path / "ds")]) == 1
    assert "16000x12000" in _err(capsys) and not (tmp_path / "ds").exists()


def test_out_of_memory_is_one_line(monkeypatch, capsys):
    import lipgen.commands.bench as bench

    def boom(args):
        raise MemoryError("Unable to allocate 225. GiB for an array with shape (999999, 30249)")

    monkeypatch.setattr(bench, "_run", boom)
    assert main(["bench"]) == 1
    err = _err(capsys)
    assert "out of memory" in err and "(999999, 30249)" in err


# ---- reconstruct --reference-frames: a huge range is refused at once ---------------------

def test_reference_frames_refuse_a_huge_or_empty_range():
    from lipgen.commands.reconstruct import _frames
    from lipgen.recon.split import training_candidates

    assert _frames("0-3,7") == [0, 1, 2, 3, 7]
    with pytest.raises(argparse.ArgumentTypeError, match="more than 1000000 frames"):
        _frames("0-1000000000")  # was a list of 10^9 ints: minutes and gigabytes before any message
    with pytest.raises(argparse.ArgumentTypeError, match="is empty"):
        _frames("5-2")
    with pytest.raises(ValueError, match=r"got 101 of 101 outside it \(e.g. 100\)$"):
        training_candidates(14, reference_frames=range(100, 201))


# ---- pictures: the format is checked before the drawing ----------------------------------

@pytest.mark.parametrize("argv", [
    ["show", "{t}/ds", "--out", "{t}/frame.txt"],
    ["show", "{t}/ds", "--out", "{t}/frame"],  # written as 'frame' before
    ["nrsfm", "{t}/t.npz", "--k", "2", "--out", "{t}/s.npz", "--plot", "{t}/curve"],
    ["mesh", "--out", "{t}/lips.obj", "--plot", "{t}/lips.txt"],  # lips.obj was written first
])
def test_a_picture_without_a_picture_format_is_refused_first(tmp_path, capsys, argv):
    import numpy as np

    np.savez(tmp_path / "t.npz", W=np.random.default_rng(0).normal(size=(20, 8)))
    before = _tree(tmp_path)
    assert main([a.format(t=tmp_path) for a in argv]) == 1
    assert "a picture's name must end in one of" in _err(capsys)
    assert _tree(tmp_path) == before


# ---- inputs named before the work ----------------------------------------------------------

def _recon_arrays(F=4, n=201, P=16):
    import numpy as np

    z = np.zeros
    return {"fields": z((F, n, 3)), "markers": z((F, P, 3)), "visible": np.ones((F, P), bool),
            "lab_points": z((F, P + 1, 3)), "ray_gap": z((F, P + 1)), "uv": z((2, F, P + 1, 2)),
            "status": z((2, F, P + 1), np.int8), "score": z((2, F, P + 1)), "frame_index": np.arange(F),
            "lab_to_board": np.eye(4), "similarity": np.eye(4), "rotations": np.tile(np.eye(3), (F, 1, 1))}


@pytest.mark.parametrize("edit, match", [
    (lambda d: d["fields"].__setitem__((1, 5, 0), float("nan")), "NaN in part of a frame"),  # was skipped
    (lambda d: d["fields"].__setitem__((2, 0, 0), float("inf")), "first: frame 2"),
    (lambda d: d.__setitem__("fields", d["fields"] + 1e300), "beyond 10000 mm"),  # was: eigh failed
    (lambda d: d.__setitem__("fields", d["fields"][:0]), r"F >= 1 frames, got float64 \(0, 201, 3\)"),
    (lambda d: d.__setitem__("fields", d["fields"].astype(str)), "fields must be float"),
    (lambda d: d.__setitem__("markers", d["markers"][:3]),
     r"markers has shape \(3, 16, 3\), expected \(4, \*, 3\)"),
    (lambda d: d["similarity"].__setitem__((0, 0), float("nan")), "similarity"),
])
def test_an_altered_reconstruction_file_is_named(edit, match):
    from lipgen.errors import ModelFileError
    from lipgen.recon.reconfile import check_recon_arrays

    d = _recon_arrays()
    d["fields"][3] = float("nan")  # a whole frame without a field is fine
    check_recon_arrays("r.npz", d)
    edit(d)
    with pytest.raises(ModelFileError, match=match):
        check_recon_arrays("r.npz", d)


def test_reconstruction_load_checks_its_arrays(tmp_path):
    import json

    import numpy as np

    from lipgen._io import save_npz
    from lipgen.errors import ModelFileError
    from lipgen.recon.pipeline import Reconstruction

    d = _recon_arrays()
    d["fields"][1, 5, 0] = np.nan
    save_npz(tmp_path / "r.npz", "lipgen.Reconstruction", 1, {**d, "info": np.array(json.dumps({}))})
    with pytest.raises(ModelFileError, match="NaN in part of a frame"):
        Reconstruction.load(tmp_path / "r.npz")


def test_lipsync_refuses_a_rate_or_seed_out_of_range(tmp_path, capsys):
    for flag, value, match in (("--rate", "1e-9", "rate must be a speaking-rate factor in [0.1, 10]"),
                               ("--rate", "nan", "got nan"),
                               ("--seed", "-1", "seed must be a whole number >= 0, got -1")):
        assert main(["lipsync", "--text", "hello", flag, value, "--out", str(tmp_path / "l.npz")]) == 1
        assert match in _err(capsys)   # --rate 1e-9 was 10^10 frames: out of memory; 1e-5 1.5 million
    assert list(tmp_path.iterdir()) == []


def test_nrsfm_refuses_a_negative_seed(tmp_path, capsys):
    import numpy as np

    np.savez(tmp_path / "t.npz", W=np.random.default_rng(0).normal(size=(20, 8)))
    assert main(["nrsfm", str(tmp_path / "t.npz"), "--k", "2", "--seed", "-1",
                 "--out", str(tmp_path / "s.npz")]) == 1
    assert "--seed must be a whole number >= 0, got -1" in _err(capsys)  # was: numpy's message


def test_export_usd_refuses_an_empty_weights_file(tmp_path, capsys):
    import numpy as np

    from lipgen.usd.export import _blend_shape_plan

    pytest.importorskip("pxr")
    from lipgen import Physics
    from lipgen.mesh.procedural import lip_mesh
    from lipgen.modes.model import ModeModel

    mesh = lip_mesh(0)
    model = ModeModel(3).fit_from_markers(Physics(mesh), np.random.default_rng(0).normal(size=(8, 16, 3)))
    with pytest.raises(ValueError, match=r"weights has no frames \(shape \(0, 3\)\)"):
        _blend_shape_plan(mesh, model, np.zeros((0, 3)), "signed")  # was: a USD of 0 frames, exit 0


def test_show_beside_a_dataset_without_truth_is_named(tmp_path, monkeypatch):
    from lipgen.dataset.pictures import save_side_by_side
    from lipgen.errors import DatasetError

    class NoTruth:  # what save_side_by_side reads of a recording (lipgen recording init)
        path = tmp_path / "rec"

        def __len__(self):
            return 3

        def require_truth(self, what):
            raise DatasetError(f"{self.path} has no ground truth: {what}")

    with pytest.raises(DatasetError, match="no ground truth: lipgen show --beside"):  # was KeyError 'uv_raw'
        save_side_by_side([NoTruth()], 0, tmp_path / "f.png")
    assert not (tmp_path / "f.png").exists()


def test_evaluate_names_a_reconstruction_off_its_mesh():
    from types import SimpleNamespace

    import numpy as np

    from lipgen.commands.evaluate import check_recon_mesh
    from lipgen.mesh.procedural import lip_mesh

    mesh = lip_mesh(0)
    recon = SimpleNamespace(fields=np.zeros((4, mesh.n_nodes, 3)), info={"mesh_source": "lip_mesh(0)"})
    check_recon_mesh(recon, mesh, "r.npz")
    recon.fields = recon.fields[:, :100]   # was: 'operands could not be broadcast together'
    with pytest.raises(ValueError, match=r"\(4, 100, 3\) have 100 nodes but its mesh lip_mesh\(0\) has 201"):
        check_recon_mesh(recon, mesh, "r.npz")


# ---- experiments: every report file needs --force; settings checked before any folder --------

@pytest.mark.parametrize("argv, picture", [
    (["experiment", "table51", "--noise-mm", "0"], "modes.png"),
    (["experiment", "table51"], "error_vs_modes_noise0.3.png"),   # two noises: suffixed pictures
    (["experiment", "nrsfm", "--no-synthetic"], "drink_curve.png"),
    (["experiment", "lipsync", "--max-sentences", "1"], "list1.png"),   # had no output check at all
])
def test_experiment_pictures_are_kept_without_force(tmp_path, capsys, argv, picture):
    (tmp_path / picture).write_bytes(b"my picture")
    assert main([*argv, "--out", str(tmp_path)]) == 1
    assert f"already holds {picture}" in _err(capsys)
    assert (tmp_path / picture).read_bytes() == b"my picture"


@pytest.mark.parametrize("opts, match", [
    (["--max-sentences", "0"], "max_sentences must be at least 1"),   # 0 ran every sentence
    (["--snr", "nan"], r"snr_db must be .* got \(nan,\)"),              # nan ran as clean speech
])
def test_lipsync_experiment_settings_are_named(tmp_path, capsys, opts, match):
    import re

    assert main(["experiment", "lipsync", *opts, "--out", str(tmp_path / "x")]) == 1
    assert re.search(match, _err(capsys)) and not (tmp_path / "x").exists()


@pytest.mark.parametrize("opts, match", [
    (["--size", "0", "0"], "size must be W x H"),          # was checked after OUT/work was made
    (["--workers", "0"], "workers must be a whole number"),
    (["--splits", "{t}/bad.json"], "bad.json is not JSON"),
    (["--work", "{t}/no/w"], "does not exist"),            # was created, with its parents
])
def test_pipeline_experiment_refuses_before_any_folder(tmp_path, capsys, opts, match):
    (tmp_path / "bad.json").write_text("{bad")
    argv = ["experiment", "table51-pipeline", "--seeds", "0", "1", "--frames", "20", "--test-frames", "30",
            *[o.format(t=tmp_path) for o in opts], "--out", str(tmp_path / "xp")]
    assert main(argv) == 1
    assert match in _err(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.json"]


# ---- campaign: options checked before the index is written; the report needs --force -----------

_PLAN = """[campaign]
name = "tiny"
stages = ["generate"]
[base]
frames = 3
size = "160x120"
calib_frames = 1
[grid]
seed = [0]
"""


@pytest.mark.parametrize("opts, match", [
    (["--workers", "0"], "got 0"),             # was: all cores
    (["--workers", "100000"], "got 100000"),   # was: refused after campaign.json was written
    (["--address", "auto"], "--address needs the ray executor"),
])
def test_campaign_options_are_checked_before_the_folder(tmp_path, capsys, opts, match):
    (tmp_path / "plan.toml").write_text(_PLAN)
    out = tmp_path / "camp"
    assert main(["campaign", str(tmp_path / "plan.toml"), "--out", str(out), "--executor", "local",
                 "--no-progress", *opts]) == 1
    assert match in _err(capsys) and not out.exists()


def test_campaign_folders_are_not_made_on_the_way_and_reports_kept(tmp_path, capsys):
    (tmp_path / "plan.toml").write_text(_PLAN)
    assert main(["campaign", str(tmp_path / "plan.toml"), "--out", str(tmp_path / "a" / "camp"),
                 "--executor", "local"]) == 1
    assert "does not exist" in _err(capsys) and not (tmp_path / "a").exists()
    assert main(["campaign", "report", str(tmp_path), "--report-out", str(tmp_path / "b" / "r")]) == 1
    assert "does not exist" in _err(capsys) and not (tmp_path / "b").exists()
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "report.md").write_text("my notes")
    assert main(["campaign", "report", str(tmp_path), "--report-out", str(mine)]) == 1
    assert "--force" in _err(capsys) and (mine / "report.md").read_text() == "my notes"


def test_mesh_views_are_checked_before_the_mesh_is_written(tmp_path, capsys):
    assert main(["mesh", "--out", str(tmp_path / "lips.obj"), "--plot", str(tmp_path / "lips.png"),
                 "--views", "front,nope"]) == 1
    assert "unknown view(s) ['nope']" in _err(capsys)
    assert list(tmp_path.iterdir()) == []   # lips.obj and its sidecar were written before the refusal


@pytest.mark.parametrize("opts, match", [
    (["--frames", "0"], "frames must be a whole number"),    # was: after the physics pictures (3 s)
    (["--workers", "0"], "workers must be a whole number"),
    (["--physics-only", "--out", "{t}/no/out"], "does not exist"),   # was: created with its parents
])
def test_demo_refuses_before_the_physics_pictures(tmp_path, capsys, opts, match):
    opts = [o.format(t=tmp_path) for o in opts]
    out = [] if "--out" in opts else ["--out", str(tmp_path / "d")]
    assert main(["demo", "--no-progress", *opts, *out]) == 1
    assert match in _err(capsys) and list(tmp_path.iterdir()) == []


def test_export_usd_fps_is_bounded_before_the_simulation(tmp_path, capsys):
    import numpy as np

    from lipgen import Physics
    from lipgen.mesh.procedural import lip_mesh
    from lipgen.modes.model import ModeModel

    rng = np.random.default_rng(0)
    ModeModel(3).fit_from_markers(Physics(lip_mesh(0)), rng.normal(size=(8, 16, 3))).save(tmp_path / "m.npz")
    # --fps 1e9 simulated 3e8 frames of a 0.3 s script: 22 s, then out of memory
    assert main(["export-usd", "--model", str(tmp_path / "m.npz"), "--script", "AA:0.3", "--fps", "1e9",
                 "--out", str(tmp_path / "s.usda")]) == 1
    assert "--fps must be in [1, 1000], got 1000000000.0" in _err(capsys)
    assert [p.name for p in tmp_path.iterdir()] == ["m.npz"]


@pytest.mark.parametrize("kw, match", [({"dot_diameter": -1.0}, "dot_diameter must be in"),
                                       ({"mesh_source": "lip_mesh(9)"}, "resolution must be in")])
def test_recording_options_are_named_before_the_footage_is_read(tmp_path, kw, match):
    from lipgen.recon.recording import init_recording

    # were checked after reading the footage and calibrating the rig (seconds on real footage)
    with pytest.raises(ValueError, match=match):
        init_recording(tmp_path / "no_footage", tmp_path / "no_boards", tmp_path / "rec", **kw)


@pytest.mark.parametrize("argv, match", [
    (["table51-splits", "--noise-px", "nan"], "marker_noise_px must be a finite number >= 0, got nan"),  # ran
    (["table51-splits", "--noise-mm", "nan"], "marker_noise_mm must be a finite number >= 0, got nan"),
    (["table51", "--noise-mm", "0", "nan"], "got nan"),   # was: after the first noise's run (8 s)
    (["table51", "--seed", "-1"], "seed must be a whole number >= 0, got -1"),
])
def test_table51_settings_are_named_before_any_run(tmp_path, capsys, argv, match):
    assert main(["experiment", *argv, "--out", str(tmp_path / "x")]) == 1
    assert match in _err(capsys) and not (tmp_path / "x").exists()


@pytest.mark.parametrize("opts", [["--speech-text", ""], ["--speech", "{t}/s.wav", "--text", ""]])
def test_generate_an_empty_transcript_is_named(tmp_path, capsys, opts):
    # '' was taken as not given: random gestures instead of speech, or recognition instead of alignment
    assert main(["generate", "--frames", "2", *[o.format(t=tmp_path) for o in opts],
                 "--out", str(tmp_path / "ds")]) == 1
    assert "is empty; give the words spoken" in _err(capsys) and not (tmp_path / "ds").exists()


def test_evaluate_checks_the_model_mesh_before_reconstructing(tmp_path, capsys):
    import numpy as np

    from lipgen.dataset.generate import generate
    from lipgen.dataset.layout import GenerateSettings
    from lipgen.mesh.procedural import lip_mesh
    from lipgen.modes.model import ModeModel

    generate(tmp_path / "ds", GenerateSettings(frames=3, size=(160, 120), calib_frames=1), progress=False)
    fine = lip_mesh(1)
    fields = np.random.default_rng(0).normal(size=(5, fine.n_nodes, 3))
    ModeModel(2).fit(fields, mesh=fine).save(tmp_path / "m.npz")
    # was found after the reconstruction (minutes on real data), with OUT/recon.npz written
    assert main(["evaluate", str(tmp_path / "ds"), "--model", str(tmp_path / "m.npz"),
                 "--out", str(tmp_path / "rep")]) == 1
    assert "has 750 nodes but mesh 'lips_r0' has 201" in _err(capsys) and not (tmp_path / "rep").exists()
