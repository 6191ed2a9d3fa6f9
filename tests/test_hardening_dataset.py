"""Hardening of the dataset folder: manifest paths stay inside, symlinks out are refused, a
refused run deletes nothing, a resume redoes damaged files, and what can fail fails before
the first write (issue 20, items 2-5 and 12)."""

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from lipgen.cli import main
from lipgen.dataset.layout import Dataset, GenerateSettings, validate_manifest
from lipgen.errors import DatasetError

pytestmark = pytest.mark.render
pytest.importorskip("lipgen.rig.render")
pytest.importorskip("lipgen.subject.motion")

SMALL = GenerateSettings(frames=3, seed=5, size=(160, 120), calib_frames=1)


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    from lipgen.dataset.generate import generate

    return generate(tmp_path_factory.mktemp("small") / "ds", SMALL, progress=False)


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


def _edit(ds: Path, edit) -> None:
    m = json.loads((ds / "manifest.json").read_text())
    edit(m)
    (ds / "manifest.json").write_text(json.dumps(m))


@pytest.mark.parametrize("bad", ["../../outside/x.png", "/etc/passwd", "raw/../../x.png", "C:\\x.png",
                                 "~/x.png", "", 7])
def test_manifest_paths_outside_the_folder_are_refused(small, tmp_path, bad):
    outside = tmp_path / "outside"
    outside.mkdir()
    shutil.copy(small / "raw" / "000000.png", outside / "x.png")
    ds = _copy(small, tmp_path / "a" / "b" / "ds")
    _edit(ds, lambda m: m["frames"][1].__setitem__("raw", bad))
    with pytest.raises(DatasetError, match="frames\\[1\\].raw"):
        Dataset(ds)
    assert main(["show", str(ds), "--frame", "1", "--out", str(tmp_path / "p.png")]) == 1
    assert not (tmp_path / "p.png").exists()


def test_a_symlink_leading_out_is_refused_by_reader_and_resume(small, tmp_path):
    from lipgen.dataset.generate import generate

    ds = _copy(small, tmp_path / "ds")
    elsewhere = tmp_path / "elsewhere"
    shutil.move(ds / "raw", elsewhere)
    (elsewhere / ".000000.png.tmp-1-unrelated").write_text("not ours")
    os.symlink(elsewhere, ds / "raw")
    with pytest.raises(DatasetError, match="outside the dataset folder"):
        Dataset(ds)[0]
    with pytest.raises(DatasetError, match="outside the dataset folder"):
        Dataset(ds).missing()
    (elsewhere / "000001.png").unlink()
    with pytest.raises(DatasetError, match="symlink"):
        generate(ds, SMALL, resume=True, progress=False)
    assert not (elsewhere / "000001.png").exists()  # nothing written through the link
    assert (elsewhere / ".000000.png.tmp-1-unrelated").read_text() == "not ours"


def test_a_refused_run_deletes_nothing(tmp_path):
    from lipgen.dataset.generate import generate

    foreign = tmp_path / "foreign"
    foreign.mkdir()
    keep = [foreign / n for n in (".manifest.json.tmp-mybackup", "notes.txt", ".manifest.json.tmp-1-x")]
    for p in keep:
        p.write_text("mine")
    with pytest.raises(DatasetError, match="nothing was written"):
        generate(foreign, SMALL, progress=False)
    assert all(p.read_text() == "mine" for p in keep)


def test_resume_redoes_damaged_files_and_cleans_temporaries(small, tmp_path):
    from lipgen.dataset.generate import generate

    ds = _copy(small, tmp_path / "ds")
    good = {p: p.read_bytes() for p in ds.rglob("*") if p.is_file() and p.name != "manifest.json"}
    (ds / "truth" / "000001.npz").write_bytes((ds / "truth" / "000001.npz").read_bytes()[:200])  # truncated
    (ds / "raw" / "000002.png").write_bytes(b"")  # empty
    half = (ds / "calib" / "000000.png").read_bytes()
    (ds / "calib" / "000000.png").write_bytes(half[: len(half) // 2])  # half a calibration PNG
    assert Dataset(ds).missing() == [1, 2]
    with pytest.raises(DatasetError, match="calib/000000.png"):
        Dataset(ds).calibration()
    dead = 2**22 + 12345  # above the default pid_max: never a running process
    for sub in ("", "raw", "truth", "calib"):
        (ds / sub / f".x.npz.tmp-{dead}-abc.npz").write_bytes(b"junk")
    generate(ds, SMALL, resume=True, progress=False)
    assert Dataset(ds).missing() == []
    after = {p: p.read_bytes() for p in ds.rglob("*") if p.is_file() and p.name != "manifest.json"}
    assert after == good  # the same bytes as the first run, and no temporary left


def test_manifest_garbage_gets_a_one_line_error(small):
    m = json.loads((small / "manifest.json").read_text())
    cases = [(lambda m: m["frames"].__setitem__(0, "raw/000000.png"), "frames\\[0\\]"),
             (lambda m: m.__setitem__("fps", "fast"), "fps must be a positive finite number"),
             (lambda m: m.__setitem__("settings", ["x"]), "bad settings"),
             (lambda m: m.__setitem__("frames", "none"), "frame list"),
             (lambda m: m["mesh"].__setitem__("file", "../mesh.npz"), "mesh.file"),
             (lambda m: m["calibration"]["frames"][0].__setitem__("truth", "/tmp/x.npz"), "calibration")]
    for edit, match in cases:
        bad = json.loads(json.dumps(m))
        edit(bad)
        with pytest.raises(DatasetError, match=match):
            validate_manifest(bad)


def test_a_size_that_cannot_calibrate_fails_before_any_write(tmp_path, capsys):
    out = tmp_path / "tiny"
    assert main(["generate", "--out", str(out), "--size", "16x12", "--frames", "1", "--calib-frames", "1",
                 "--no-progress"]) == 1
    assert "board poses" in capsys.readouterr().err
    assert not out.exists()


def test_generate_writes_scan_no_folder_but_a_chunk_retry_cleans_its_files(small, tmp_path, monkeypatch):
    """generate's own writes do not look for leftovers file by file (the folder was cleaned when
    prepared; a scan per file grows with the folder), with 1 worker; a campaign chunk
    (``render_jobs``, perhaps retrying a killed worker's frames) still removes a dead writer's
    temporary file of each frame it writes."""
    from lipgen import _io
    from lipgen.dataset import generate as gen

    scans = []
    real = _io.remove_stale_temporaries
    monkeypatch.setattr(_io, "remove_stale_temporaries",
                        lambda dest, folder=False: scans.append((Path(dest), folder)) or real(dest, folder))
    out = gen.generate(tmp_path / "one", SMALL, progress=False)
    per_file = [d for d, folder in scans if not folder and d.parent.name in ("raw", "truth", "calib")]
    assert per_file == []
    assert _files_equal(out, small)

    ds = _copy(small, tmp_path / "retry")
    dead = 2**22 + 54321  # above the default pid_max: never a running process
    left = ds / "raw" / f".000001.png.tmp-{dead}-abc.png"
    left.write_bytes(b"half a frame")
    (ds / "truth" / "000001.npz").unlink()
    ctx, jobs = gen.prepare_dataset(ds, SMALL, resume=True)  # cleans the folder ...
    assert jobs == [("frame", 1)] and not left.exists()
    left.write_bytes(b"half a frame")  # ... and a worker killed after the preparation leaves one again
    try:
        assert gen.render_jobs(ctx, jobs) == 1
    finally:
        gen._close_worker()
    assert not left.exists() and _files_equal(ds, small)


def _files_equal(a: Path, b: Path) -> bool:
    names = {p.relative_to(a) for p in a.rglob("*") if p.is_file()}
    return names == {p.relative_to(b) for p in b.rglob("*") if p.is_file()} and all(
        (a / n).read_bytes() == (b / n).read_bytes() for n in names if n.name != "manifest.json")


def test_the_truth_physics_bar_follows_the_callers_progress(capsys):
    """``lipgen generate --no-progress`` printed the hard preset's "truth physics" bar all the same:
    the bar was on whenever the nonlinear physics ran, whatever the caller asked."""
    from lipgen.dataset.simulation import simulate_motion

    hard = GenerateSettings.from_preset("hard", frames=2, seed=3)
    quiet = simulate_motion(hard, progress=False)
    assert "truth physics" not in capsys.readouterr().err
    loud = simulate_motion(hard, progress=True)
    assert "truth physics" in capsys.readouterr().err
    np.testing.assert_array_equal(quiet.vertices_world, loud.vertices_world)  # the bar changes nothing else


@pytest.mark.parametrize("content, resume, match", [
    ({"manifest.json": "{}"}, False, "already holds a dataset"),
    ({"notes.txt": "mine"}, False, "not a lipgen dataset"),
    ({"manifest.json": "{not json"}, True, "not readable JSON"),
])
def test_an_occupied_folder_is_refused_before_the_truth_physics(tmp_path, monkeypatch, content, resume,
                                                                 match):
    # the refusal must not wait for the subject's simulation (about 30 s on the hard preset)
    import lipgen.dataset.generate as gen

    def simulated(*a, **k):
        raise AssertionError("the truth physics ran before the folder was checked")

    monkeypatch.setattr(gen, "simulate_motion", simulated)
    out = tmp_path / "d"
    out.mkdir()
    for name, text in content.items():
        (out / name).write_text(text)
    with pytest.raises(DatasetError, match=match):
        gen.generate(out, SMALL, resume=resume, progress=False)
    assert {p.name: p.read_text() for p in out.iterdir()} == content


def test_a_frame_of_another_size_is_named_with_its_file(small, tmp_path):
    """It was met in the tracking as 'raw frame must have shape (120, 160) ..., got (80, 100, 3)',
    naming no file (harden20)."""
    from PIL import Image

    ds = _copy(small, tmp_path / "ds")
    Image.new("RGB", (100, 80)).save(ds / "raw" / "000001.png")
    d = Dataset(ds)
    d[0]
    with pytest.raises(DatasetError, match=r"000001.png is 100x80 but the dataset's frames are 160x120"):
        d[1]


def test_resuming_with_other_settings_is_refused_before_the_truth_physics(small, tmp_path, monkeypatch):
    """--resume with another seed was refused only after the subject's simulation (about 30 s on
    the hard preset): the settings are compared before it now (harden20)."""
    from dataclasses import replace

    import lipgen.dataset.generate as gen

    def simulated(*a, **k):
        raise AssertionError("the truth physics ran before the settings were compared")

    ds = _copy(small, tmp_path / "ds")
    monkeypatch.setattr(gen, "simulate_motion", simulated)
    with pytest.raises(DatasetError, match="different settings .*seed was 5, now 6"):
        gen.generate(ds, replace(SMALL, seed=6), resume=True, progress=False)
    with pytest.raises(AssertionError, match="truth physics ran"):  # the same settings go on to simulate
        gen.generate(ds, SMALL, resume=True, progress=False)


def test_a_board_that_cannot_be_placed_is_refused_before_the_truth_physics(tmp_path, monkeypatch):
    """A --size too small for the chessboard was found after the subject's simulation (harden20)."""
    import lipgen.dataset.generate as gen

    def simulated(*a, **k):
        raise AssertionError("the truth physics ran before the board was placed")

    monkeypatch.setattr(gen, "simulate_motion", simulated)
    with pytest.raises(ValueError, match="board poses that both views see whole"):
        gen.generate(tmp_path / "d", GenerateSettings(frames=2, size=(32, 24), calib_frames=1),
                     progress=False)
    assert not (tmp_path / "d").exists()
