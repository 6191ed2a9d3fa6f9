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
    ["show", "{d}", "--recon", "{t}/r.npz", "--out", "{t}/r.npz"],
    ["reconstruct", "{d}", "--out", "{d}/mesh.npz"],                            # the dataset's mesh
    ["reconstruct", "{d}", "--rest-from", "{t}/r.npz", "--out", "{t}/r.npz"],
    ["evaluate", "{d}", "--model", "{t}/rep/recon.npz", "--out", "{t}/rep"],   # writes rep/recon.npz
    ["show", "{d}", "--out", "{t}/link.png"],                                   # a symlink into the dataset
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
