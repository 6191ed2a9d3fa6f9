"""Options and settings checked before the run, not after it (audit harden20): experiments, campaign,
demo, mesh, export-usd, recording init, generate and evaluate refuse a bad value before any work or
folder, and report files need --force."""

import pytest

from lipgen.cli import main


def _err(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err


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


@pytest.mark.parametrize("argv", [["lipsync", "--text", "hello"], ["export-usd", "--points", "{t}/p.npy"]])
def test_a_start_time_code_beyond_doubles_is_refused(tmp_path, capsys, argv):
    import numpy as np

    np.save(tmp_path / "p.npy", np.zeros((3, 201, 3)))
    # at 1e20 every frame fell on one time code (start == end), written with exit 0
    assert main([*[a.format(t=tmp_path) for a in argv], "--start", str(10**20),
                 "--out", str(tmp_path / "s.usda")]) == 1
    assert "start time code 100000000000000000000 is beyond" in _err(capsys)
    assert not (tmp_path / "s.usda").exists()


def test_reconstruct_recording_and_out_the_same_path_is_refused_first(tmp_path, capsys, monkeypatch):
    import lipgen.recon.recording as recording

    def made(*a, **k):
        raise AssertionError("the recording was made, then the reconstruction could not be saved")

    monkeypatch.setattr(recording, "init_recording", made)
    (tmp_path / "frames").mkdir()
    (tmp_path / "boards").mkdir()
    out = str(tmp_path / "r.npz")
    assert main(["reconstruct", str(tmp_path / "frames"), "--calib", str(tmp_path / "boards"), "--out", out,
                 "--recording", out]) == 1
    assert "--recording" in _err(capsys) and not (tmp_path / "r.npz").exists()


def test_lipsync_refuses_a_rate_with_a_recording(tmp_path, capsys):
    # --rate paces text alone; with audio it was silently ignored
    import numpy as np
    from scipy.io import wavfile

    wav = tmp_path / "s.wav"
    wavfile.write(wav, 16000, np.zeros(1600, np.int16))
    out = tmp_path / "o.usda"
    assert main(["lipsync", str(wav), "--text", "hello", "--rate", "1.5", "--out", str(out)]) == 1
    assert "--rate 1.5 sets the pace of text alone" in _err(capsys) and not out.exists()


def test_lipsync_api_refuses_a_rate_with_audio():
    import numpy as np

    from lipgen.speech.audio import Audio
    from lipgen.speech.lipsync import lipsync

    with pytest.raises(ValueError, match="rate 1.5 sets the pace of text alone"):
        lipsync(Audio(np.zeros(1600), 16000), "hello", rate=1.5)
