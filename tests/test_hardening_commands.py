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


def test_force_replaces_a_commands_own_output_inside_a_dataset(tmp_path, ds, capsys):
    # DATASET/recon.npz is not part of the dataset: a second run with --force may replace it,
    # while the dataset's own files stay protected (above)
    from lipgen.commands._output import check_not_input

    (ds / "recon.npz").write_bytes(b"an earlier reconstruction")
    check_not_input(ds / "recon.npz", (ds,))
    check_not_input(ds / "report" / "frame.png", (ds,))
    for part in ("manifest.json", "mesh.npz", "raw/000000.png"):
        with pytest.raises(ValueError, match="is a file of the input"):
            check_not_input(ds / part, (ds,))
    photos = tmp_path / "photos"                       # not a dataset: every file is the input
    photos.mkdir()
    (photos / "board.png").write_bytes(b"a photo")
    with pytest.raises(ValueError, match="is a file of the input"):
        check_not_input(photos / "board.png", (photos,))


def test_a_picture_without_an_extension_is_a_png(tmp_path):
    import numpy as np

    np.savez(tmp_path / "t.npz", W=np.random.default_rng(0).normal(size=(20, 8)))
    assert main(["nrsfm", str(tmp_path / "t.npz"), "--k", "2", "--out", str(tmp_path / "s.npz"),
                 "--plot", str(tmp_path / "curve")]) == 0
    assert (tmp_path / "curve").read_bytes()[:4] == b"\x89PNG"


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


@pytest.mark.parametrize("case", ["the photos", "holds the footage", "foreign folder", "missing parent",
                                  "generated dataset"])
def test_recording_out_is_checked_before_anything_is_replaced(tmp_path, case):
    for name in ("frames", "boards", "mine", "generated"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "a.png").write_bytes(name.encode())
    (tmp_path / "generated" / "manifest.json").write_text('{"source": "synthetic"}')   # it has truth
    before = _tree(tmp_path)
    out, error, match = {
        "the photos": (tmp_path / "boards", ValueError, "overlaps --calib"),
        "holds the footage": (tmp_path, ValueError, "overlaps the footage"),
        "foreign folder": (tmp_path / "mine", FileExistsError, "holds other files"),
        "missing parent": (tmp_path / "no" / "rec", FileNotFoundError, "does not exist"),
        "generated dataset": (tmp_path / "generated", FileExistsError, "not a recording.*'synthetic'"),
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
    ["nrsfm", "{t}/t.npz", "--k", "2", "--out", "{t}/s.npz", "--plot", "{t}/curve.txt"],
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

    from lipgen.evaluate.scoring import check_recon_mesh
    from lipgen.mesh.procedural import lip_mesh

    mesh = lip_mesh(0)
    recon = SimpleNamespace(fields=np.zeros((4, mesh.n_nodes, 3)), info={"mesh_source": "lip_mesh(0)"})
    check_recon_mesh(recon, mesh)
    recon.fields = recon.fields[:, :100]   # was: 'operands could not be broadcast together'
    with pytest.raises(ValueError, match=r"\(4, 100, 3\) have 100 nodes but its mesh lip_mesh\(0\) has 201"):
        check_recon_mesh(recon, mesh)


def test_nrsfm_plot_and_out_the_same_file_is_refused(tmp_path, capsys):
    import numpy as np

    np.savez(tmp_path / "t.npz", W=np.random.default_rng(0).normal(size=(20, 8)))
    out = str(tmp_path / "c.png")
    # the shapes (an npz) were written over the curve's picture, exit 0
    assert main(["nrsfm", str(tmp_path / "t.npz"), "--k", "2", "--out", out, "--plot", out]) == 1
    assert "is --out too" in _err(capsys) and not (tmp_path / "c.png").exists()


def test_recording_in_a_read_only_folder_is_refused_first(tmp_path, monkeypatch):
    import lipgen.recon.recording as recording

    ro = tmp_path / "ro"
    ro.mkdir()
    monkeypatch.setattr(recording.os, "access", lambda p, mode: Path(p) != ro)  # root writes anywhere
    with pytest.raises(PermissionError, match="is not writable"):  # was: after reading and calibrating
        recording.init_recording(tmp_path / "frames", tmp_path / "boards", ro / "rec")


def test_lipsync_out_a_folder_is_refused_before_the_work(tmp_path, capsys, monkeypatch):
    import importlib

    lipsync = importlib.import_module("lipgen.speech.lipsync")  # the module, not the function

    def worked(*a, **k):
        raise AssertionError("the lip sync ran before --out was checked")

    monkeypatch.setattr(lipsync, "lipsync", worked)
    (tmp_path / "d.npz").mkdir()
    assert main(["lipsync", "--text", "hello", "--out", str(tmp_path / "d.npz"), "--force"]) == 1
    assert "is a folder" in _err(capsys)


def test_the_recording_folder_is_named_by_the_callers_flag(tmp_path):
    # reconstruct builds the recording in --recording (or OUT_recording): its messages say so
    from lipgen.recon.recording import check_recording_out

    video, calib = tmp_path / "clip.mp4", tmp_path / "photos"
    with pytest.raises(FileNotFoundError, match=r"^--recording .*missing.* does not exist"):
        check_recording_out(tmp_path / "missing" / "rec", video, calib, False, "--recording")
    with pytest.raises(ValueError, match=r"^--out .* overlaps --calib"):
        check_recording_out(calib, video, calib, True)


@pytest.mark.parametrize("case", ["footage", "not empty"])
def test_reconstruct_refuses_its_recording_folder_before_any_work(tmp_path, capsys, case):
    # the command leaves these checks to init_recording, which makes them before reading anything
    frames, boards = tmp_path / "frames", tmp_path / "boards"
    for folder in (frames, boards):
        folder.mkdir()
        (folder / "0.png").write_bytes(b"not read")
    rec = frames if case == "footage" else tmp_path / "rec"
    if case == "not empty":
        rec.mkdir()
        (rec / "keep.txt").write_text("mine")
    before = sorted((p, p.read_bytes()) for p in tmp_path.rglob("*") if p.is_file())
    status = main(["reconstruct", str(frames), "--calib", str(boards), "--recording", str(rec),
                   "--out", str(tmp_path / "r.npz"), "--no-progress"])
    err = _err(capsys)
    assert status == 1 and "--recording" in err
    assert ("overlaps the footage" if case == "footage" else "holds other files") in err
    assert sorted((p, p.read_bytes()) for p in tmp_path.rglob("*") if p.is_file()) == before
