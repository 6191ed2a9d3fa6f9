"""``lipgen experiment tracking``: the tracker scored over generated sets against issue 15's targets.

One tiny run (preset easy, seeds 0 and 1, 6 frames, 6 calibration frames) is made once for the
module; its figures are checked against ``lipgen evaluate``'s tracking table on the same
reconstruction, also after sightings were moved and lost by hand (so that the > 3 px, rejected and
lost counts are not all zero), and a second run must reuse its datasets.
"""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from lipgen._gitinfo import code_version
from lipgen.cli import main
from lipgen.errors import DatasetError
from lipgen.experiments.tracking import TARGETS, pooled_figures, spread, targets_met

pytestmark = pytest.mark.render
TINY = ["--preset", "easy", "--frames", "6", "--calib-frames", "6", "--no-progress"]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    pytest.importorskip("cv2")
    from lipgen.rig.render import import_pyrender

    try:
        import_pyrender()
    except Exception as exc:  # no GL here: the rendering tests cannot run
        pytest.skip(f"no offscreen rendering: {exc}")
    root = tmp_path_factory.mktemp("tracking_exp")
    assert main(["experiment", "tracking", "--seeds", "0", "1", *TINY, "--out", str(root / "out")]) == 0
    return root, json.loads((root / "out" / "tracking.json").read_text())


def _evaluate_tracking(root, label, recon_file, name):
    """``lipgen evaluate``'s tracking table (report.json) of ``recon_file`` on the set ``label``."""
    ds = root / "out" / "work" / label
    model = root / f"{name}_model.npz"
    assert main(["train", str(recon_file), "--out", str(model), "--modes", "2", "--test-frames", "2"]) == 0
    rep = root / f"{name}_report"
    assert main(["evaluate", str(ds), "--model", str(model), "--recon", str(recon_file), "--test-frames", "2",
                 "--out", str(rep)]) == 0
    return json.loads((rep / "report.json").read_text())["tracking"]


_TABLE_KEYS = ("rms_px", "p95_px", "tracked_share", "accepted", "rejected", "lost", "wrong_over_3px",
               "false_sightings")


def _check_against(fig, table):
    for view in ("virtual", "real"):
        for k in _TABLE_KEYS:
            assert fig["per_view"][view][k] == pytest.approx(table[view][k], rel=1e-12), (view, k)
    # both views pooled, from evaluate's per-view counts
    assert fig["accepted"] == sum(table[v]["accepted"] for v in table)
    assert fig["over_3px"] == sum(table[v]["wrong_over_3px"] for v in table)
    assert fig["rejected"] == sum(table[v]["rejected"] for v in table)
    assert fig["lost"] == sum(table[v]["lost"] for v in table)
    visible = sum(table[v]["accepted"] / table[v]["tracked_share"] for v in table)
    assert fig["visible"] == round(visible)
    assert fig["accepted_share"] == pytest.approx(fig["accepted"] / visible)
    rms = np.sqrt(sum(table[v]["accepted"] * table[v]["rms_px"] ** 2 for v in table) / fig["accepted"])
    assert fig["rms_px"] == pytest.approx(rms, rel=1e-9)


def test_figures_equal_evaluates_tracking_table(run):
    root, result = run
    s0 = result["sets"][0]
    assert s0["label"] == "easy_s0" and s0["reused"] is False
    table = _evaluate_tracking(root, "easy_s0", root / "out" / "work" / "easy_s0.recon.npz", "plain")
    _check_against(s0, table)
    assert s0["tracking_cpu_ms_per_frame"] > 0


def test_figures_equal_evaluate_on_damaged_tracks(run):
    """Sightings moved by 5 px and sightings lost: the counts over 3 px and lost are not zero, and the
    experiment's figures still equal evaluate's on that reconstruction."""
    from lipgen.experiments.tracking import set_figures
    from lipgen.recon.pipeline import Reconstruction

    root, _ = run
    work = root / "out" / "work"
    recon = Reconstruction.load(work / "easy_s1.recon.npz")
    uv, status = recon.uv.copy(), recon.status.copy()
    visible, gap = recon.visible.copy(), recon.ray_gap.copy()
    uv[0, 1:4, 2, 0] += 5.0       # virtual view: mark 2 of frames 1-3 moved 5 px in u
    uv[1, 0, :5, 1] += 3.5        # real view: marks 0-4 of frame 0 moved 3.5 px in v
    status[1, 4, 7] = 3           # real view: mark 7 of frame 4 lost: as the tracker leaves it, no
    uv[1, 4, 7] = np.nan          # position, and no longer seen in both views (not triangulated)
    visible[4, 7], gap[4, 7] = False, np.nan
    damaged = replace(recon, uv=uv, status=status, visible=visible, ray_gap=gap)
    file = root / "damaged.recon.npz"
    damaged.save(file)
    fig, errors = set_figures(work / "easy_s1", damaged)
    table = _evaluate_tracking(root, "easy_s1", file, "damaged")
    _check_against(fig, table)
    assert fig["over_3px"] == 3 + 5 and fig["lost"] >= 1
    _check_against_truth_files(work / "easy_s1", damaged, fig)
    assert fig["within_3px"] == fig["accepted"] - 8
    assert not fig["targets"]["over_3px"]
    # the errors kept for the picture: every accepted sighting once, the moved ones among them
    assert sum(len(e) for e in errors.values()) == fig["accepted"]
    assert (errors["virtual"] > 3).sum() == 3 and (errors["real"] > 3).sum() == 5


def test_report_files_and_targets(run):
    root, result = run
    out = root / "out"
    assert {p.name for p in out.iterdir()} >= {"tracking.md", "tracking.json", "tracking.png"}
    md = (out / "tracking.md").read_text()
    assert "easy_s0" in md and "easy_s1" in md and "all sets pooled" in md and "at least 3 seeds" in md
    assert result["settings"]["seeds"] == [0, 1] and result["settings"]["frames"] == 6
    assert result["code"]["lipgen"] and len(result["load"]["start"]) == 3
    pooled = result["pooled"]
    assert pooled["visible"] == sum(s["visible"] for s in result["sets"])
    assert pooled["accepted_share"] == pytest.approx(pooled["accepted"] / pooled["visible"])
    for s in [*result["sets"], pooled]:
        assert s["targets"] == targets_met(s)


def test_rerun_reuses_the_datasets(run, monkeypatch, capsys):
    root, first = run
    raw = root / "out" / "work" / "easy_s0" / "raw" / "000000.png"
    stamp = raw.stat().st_mtime_ns

    def no_generation(*a, **k):
        raise AssertionError("generate called on a cached dataset")

    monkeypatch.setattr("lipgen.dataset.generate.generate", no_generation)
    out2 = root / "out2"
    argv = ["experiment", "tracking", "--seeds", "0", "1", *TINY, "--out", str(out2), "--work",
            str(root / "out" / "work")]
    recon = root / "out" / "work" / "easy_s0.recon.npz"
    recon_stamp = recon.stat().st_mtime_ns
    assert main(argv) == 1  # the reconstructions of the first run are kept without --force
    err = capsys.readouterr().err
    assert "easy_s0.recon.npz" in err and "--force" in err
    assert recon.stat().st_mtime_ns == recon_stamp and not out2.exists()
    assert main([*argv, "--force"]) == 0
    again = json.loads((out2 / "tracking.json").read_text())
    assert [s["reused"] for s in again["sets"]] == [True, True]
    current = code_version()["git_commit"]  # the sidecar names the commit that generated each set
    assert [s["generated_by"]["git_commit"] for s in again["sets"]] == [current, current]
    assert "generated at commit" in (out2 / "tracking.md").read_text()
    assert raw.stat().st_mtime_ns == stamp
    for a, b in zip(first["sets"], again["sets"], strict=True):  # the tracker is deterministic
        assert (a["accepted"], a["over_3px"], a["rms_px"]) == (b["accepted"], b["over_3px"], b["rms_px"])


def _nothing_written(tmp_path, before):
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before


@pytest.mark.parametrize("argv, named", [
    (["--preset", "medium", "--seeds", "0"], "'medium'"),
    (["--seeds", "-3"], "-3"),
    (["--seeds", "4", "4"], "[4, 4]"),
    (["--seeds", "0", "--frames", "2"], "--frames must be a whole number >= 3, got 2"),
    (["--datasets", "{tmp}/not_a_set"], "not_a_set"),
    (["--datasets", "{tmp}", "--preset", "hard"], "--preset"),
    (["--seeds", "0", "--work", "{tmp}/a_file"], "a_file is a file"),
    (["--seeds", "0", "--calib-frames", "0"], "--calib-frames 0"),
    (["--seeds", "0", "--calib-frames", "12", "--lens-frames", "10"], "leaves 2"),
    (["--seeds", "0", "--work", "{tmp}/typo/deeper/work"], "does not exist"),
])
def test_bad_inputs_are_refused_before_any_work(tmp_path, capsys, argv, named):
    (tmp_path / "not_a_set").mkdir()
    (tmp_path / "a_file").write_text("")
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    status = main(["experiment", "tracking", *argv, "--out", str(tmp_path / "out"), "--no-progress"])
    assert status == 1
    assert named in capsys.readouterr().err
    _nothing_written(tmp_path, before)


def test_existing_report_is_kept_without_force(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "tracking.md").write_text("old")
    status = main(["experiment", "tracking", "--seeds", "0", *TINY, "--out", str(out)])
    assert status == 1 and "tracking.md" in capsys.readouterr().err
    assert (out / "tracking.md").read_text() == "old" and sorted(out.iterdir()) == [out / "tracking.md"]


def test_work_folder_with_other_settings_is_refused(run, capsys):
    """A cached set made with other settings (here 6 frames, asked 7): refused, naming the setting,
    and neither it nor the report folder touched."""
    root, _ = run
    work = root / "out" / "work"
    manifest = (work / "easy_s0" / "manifest.json").read_text()
    out3 = root / "out3"
    status = main(["experiment", "tracking", "--seeds", "0", "--preset", "easy", "--frames", "7",
                   "--calib-frames", "6", "--out", str(out3), "--work", str(work), "--no-progress"])
    err = capsys.readouterr().err
    assert status == 1 and "easy_s0" in err and "frames" in err and "never overwritten" in err
    assert "--work" in err
    assert not out3.exists() and (work / "easy_s0" / "manifest.json").read_text() == manifest


def test_pooled_and_spread_by_hand():
    """Two made-up sets: pooled counts add, the pooled RMS is over all sightings, the spread is the
    sample standard deviation."""
    def made(errs_v, errs_r, visible, lost):
        acc = np.concatenate([errs_v, errs_r])
        per_view = {v: {"rms_px": float(np.sqrt(np.mean(e ** 2))), "accepted": len(e), "visible": vis}
                    for v, e, vis in (("virtual", errs_v, visible[0]), ("real", errs_r, visible[1]))}
        fig = {"frames": 10, "visible": sum(visible), "accepted": len(acc), "rejected": 0, "lost": lost,
               "false_sightings": 0, "within_3px": int((acc <= 3).sum()), "over_3px": int((acc > 3).sum()),
               "rms_px": float(np.sqrt(np.mean(acc ** 2))), "tracking_cpu_ms_per_frame": 100.0,
               "per_view": per_view}
        fig["accepted_share"] = fig["accepted"] / fig["visible"]
        fig["within_3px_share"] = fig["within_3px"] / fig["visible"]
        return fig, {"virtual": errs_v, "real": errs_r}

    a, ea = made(np.array([0.3, 0.4]), np.array([0.5]), (2, 2), 1)
    b, eb = made(np.array([4.0]), np.array([0.1, 0.2, 0.2]), (2, 3), 1)
    p = pooled_figures([a, b], [ea, eb])
    assert (p["visible"], p["accepted"], p["over_3px"], p["within_3px"]) == (9, 7, 1, 6)
    assert p["rms_px"] == pytest.approx(np.sqrt((0.09 + 0.16 + 0.25 + 16 + 0.01 + 0.04 + 0.04) / 7))
    assert p["per_view"]["virtual"]["tracked_share"] == pytest.approx(3 / 4)
    assert p["targets"] == {"rms_px": False, "accepted_share": False, "over_3px": False}
    sp = spread([a, b])
    assert sp["accepted_share"]["mean"] == pytest.approx((3 / 4 + 4 / 5) / 2)
    assert sp["accepted_share"]["std"] == pytest.approx(np.std([3 / 4, 4 / 5], ddof=1))
    assert sp["over_3px"]["max"] == 1 and sp["over_3px"]["min"] == 0
    assert TARGETS == {"rms_px": 0.5, "accepted_share": 0.97, "over_3px": 0}


def test_existing_datasets_are_scored_alike(run):
    """--datasets on the sets the seeds run made: the same figures, named by folder."""
    root, first = run
    work = root / "out" / "work"
    out4 = root / "out4"
    assert main(["experiment", "tracking", "--datasets", str(work / "easy_s0"), str(work / "easy_s1"),
                 "--work", str(root / "work4"), "--out", str(out4), "--no-progress"]) == 0
    again = json.loads((out4 / "tracking.json").read_text())
    assert [s["label"] for s in again["sets"]] == ["easy_s0", "easy_s1"]
    assert [s["seed"] for s in again["sets"]] == [0, 1] and again["settings"]["datasets"]
    assert again["settings"]["preset"] is None and again["settings"]["frames"] is None
    assert [s["reused"] for s in again["sets"]] == [None, None]
    for a, b in zip(first["sets"], again["sets"], strict=True):
        assert (a["visible"], a["accepted"], a["over_3px"], a["rms_px"]) == (
            b["visible"], b["accepted"], b["over_3px"], b["rms_px"])


def test_incomplete_dataset_is_refused(run, tmp_path, capsys):
    import shutil

    root, _ = run
    part = tmp_path / "part"
    shutil.copytree(root / "out" / "work" / "easy_s0", part)
    (part / "raw" / "000002.png").unlink()
    status = main(["experiment", "tracking", "--datasets", str(part), "--out", str(tmp_path / "o"),
                   "--no-progress"])
    err = capsys.readouterr().err
    assert status == 1 and "part: 1 frame is missing (e.g. frame 2)" in err
    assert not (tmp_path / "o").exists()


def _check_against_truth_files(ds_path, recon, fig):
    """The figures recomputed straight from the truth files, not through lipgen.evaluate: the error
    of every accepted, truly visible sighting, the count over 3 px, the RMS per view, and the
    partition of the visible sightings into accepted, rejected and lost per view."""
    F = recon.uv.shape[1]
    files = [np.load(ds_path / "truth" / f"{i:06d}.npz") for i in range(F)]
    true_uv = np.stack([z["uv"] for z in files], axis=1)                   # (2, F, P + 1, 2)
    truly = np.stack([z["visible"] for z in files], axis=1).astype(bool)  # (2, F, P + 1)
    P = recon.visible.shape[1]
    both = np.zeros(recon.ray_gap.shape, dtype=bool)  # seen in both views, rays agree, not a pose outlier
    both[:, :P] = recon.visible
    for f, p in recon.info["normalisation"]["outliers"]:
        both[f, p] = False
    both[:, P] = recon.ray_gap[:, P] <= recon.info["ray_gap_limit_mm"]
    over, n_acc = 0, 0
    for v, view in enumerate(("virtual", "real")):
        ok = truly[v] & both
        err = np.linalg.norm(recon.uv[v][ok] - true_uv[v][ok], axis=-1)
        t = fig["per_view"][view]
        assert t["accepted"] == ok.sum() and t["wrong_over_3px"] == (err > 3).sum()
        assert t["rms_px"] == pytest.approx(np.sqrt(np.mean(err ** 2)), rel=1e-9)
        lost = truly[v] & (recon.status[v] == 3)
        assert t["lost"] == lost.sum() and t["visible"] == truly[v].sum()
        assert t["accepted"] + t["rejected"] + t["lost"] == t["visible"]
        over, n_acc = over + (err > 3).sum(), n_acc + ok.sum()
    assert (fig["over_3px"], fig["accepted"], fig["visible"]) == (over, n_acc, truly.sum())
    nose = truly[:, :, P].sum()  # the nose is among the visible sightings; markers_only leaves it out
    assert fig["markers_only"]["visible"] == truly.sum() - nose and nose > 0
    assert fig["markers_only"]["accepted"] == n_acc - (truly[:, :, P] & both[:, P]).sum()


def test_every_set_against_its_truth_files(run):
    from lipgen.recon.pipeline import Reconstruction

    root, result = run
    for s in result["sets"]:
        recon = Reconstruction.load(root / "out" / "work" / f"{s['label']}.recon.npz")
        _check_against_truth_files(root / "out" / "work" / s["label"], recon, s)


def test_rms_target_is_judged_per_view():
    """Pooled 0.49 px, but one view at 0.55 px: not met (issue 15 asks <= 0.5 px in each view)."""
    fig = {"rms_px": 0.49, "accepted_share": 0.99, "over_3px": 0,
           "per_view": {"virtual": {"rms_px": 0.55}, "real": {"rms_px": 0.40}}}
    assert targets_met(fig) == {"rms_px": False, "accepted_share": True, "over_3px": True}
    fig["per_view"]["virtual"]["rms_px"] = 0.5
    assert targets_met(fig)["rms_px"]
    fig["per_view"]["real"]["rms_px"] = float("nan")  # no accepted sighting in a view: not met
    assert not targets_met(fig)["rms_px"]


def test_error_figures_and_shares_closed_form():
    from lipgen.evaluate.error_stats import error_figures, share

    f = error_figures(np.array([3.0, 4.0, np.nan, 0.0, 5.0]))
    assert f["rms_px"] == pytest.approx(np.sqrt(50 / 4)) and f["over_3px"] == 2
    assert f["p95_px"] == pytest.approx(np.percentile([0.0, 3.0, 4.0, 5.0], 95))
    empty = error_figures(np.zeros(0))
    assert np.isnan(empty["rms_px"]) and np.isnan(empty["p95_px"]) and empty["over_3px"] == 0
    assert share(3, 4) == 0.75 and np.isnan(share(0, 0))


def test_tracking_json_is_strict():
    """NaN and infinity become null (json.loads with parse_constant refusing them reads it)."""
    from lipgen._io import strict_json as _strict

    def refuse(name):
        raise ValueError(name)

    x = _strict({"a": [float("nan"), 1.5, np.float64(np.inf)], "b": np.int64(3), "c": "s", "d": None})
    assert x == {"a": [None, 1.5, None], "b": 3, "c": "s", "d": None}
    json.loads(json.dumps(x), parse_constant=refuse)


def test_report_json_files_are_strict(run):
    root, _ = run

    def refuse(name):
        raise ValueError(f"bare {name} in tracking.json")

    json.loads((root / "out" / "tracking.json").read_text(), parse_constant=refuse)


def test_settings_from_python_take_datasets_without_seeds(run, tmp_path, monkeypatch):
    """TrackingSettings(datasets=...) needs no seeds=() (the default seeds are the CLI's); a dataset
    given as "." is named after its folder."""
    from lipgen.experiments.tracking_inputs import TrackingSettings, check_inputs

    root, _ = run
    ds = root / "out" / "work" / "easy_s0"
    plan = check_inputs(TrackingSettings(datasets=(str(ds),)), tmp_path / "w")
    assert [(label, path) for label, path, _ in plan] == [("easy_s0", ds)]
    monkeypatch.chdir(ds)
    assert [label for label, _, _ in check_inputs(TrackingSettings(datasets=(".",)), tmp_path / "w")] == [
        "easy_s0"]
    with pytest.raises(ValueError, match="give at least one seed"):
        check_inputs(TrackingSettings(), tmp_path / "w")


def test_inputs_are_checked_once(run, monkeypatch):
    """--datasets: check_inputs (which decodes every file) runs once per run."""
    import lipgen.experiments.tracking_inputs as ti

    root, _ = run
    calls = []
    real = ti.check_inputs

    def counting(*a, **k):
        calls.append(1)
        return real(*a, **k)

    monkeypatch.setattr(ti, "check_inputs", counting)
    monkeypatch.setattr("lipgen.experiments.tracking.check_inputs", counting)
    assert main(["experiment", "tracking", "--datasets", str(root / "out" / "work" / "easy_s1"), "--work",
                 str(root / "work5"), "--out", str(root / "out5"), "--no-progress"]) == 0
    assert len(calls) == 1


def _damaged_copy(run, tmp_path, damage):
    import shutil

    root, _ = run
    part = tmp_path / "part"
    shutil.copytree(root / "out" / "work" / "easy_s0", part)
    damage(part)
    return part


def _drop_calib(part):
    (part / "calib" / "000001.png").unlink()


def _bad_marks(part):
    m = json.loads((part / "manifest.json").read_text())
    m["marks"] = m["marks"][:-2] + ["nose"]
    (part / "manifest.json").write_text(json.dumps(m))


@pytest.mark.parametrize("damage, named", [(_drop_calib, "calib/000001.png"), (_bad_marks, "marks")])
def test_given_dataset_checked_up_front(run, tmp_path, capsys, damage, named):
    """A given set without a calibration image, or whose marks are not its mesh's: refused before any
    set is reconstructed (the good set given first is not reconstructed: no work folder)."""
    root, _ = run
    part = _damaged_copy(run, tmp_path, damage)
    status = main(["experiment", "tracking", "--datasets", str(root / "out" / "work" / "easy_s1"), str(part),
                   "--work", str(tmp_path / "w"), "--out", str(tmp_path / "o"), "--no-progress"])
    err = capsys.readouterr().err
    assert status == 1 and named in err and "part" in err
    assert not (tmp_path / "w").exists() and not (tmp_path / "o").exists()


def test_cached_set_with_another_rig_is_refused(run, tmp_path, capsys):
    """The same settings but another rig in the manifest (or schema, frames, calibration): refused."""
    import shutil

    root, _ = run
    work = tmp_path / "w"
    shutil.copytree(root / "out" / "work" / "easy_s0", work / "easy_s0")
    m = json.loads((work / "easy_s0" / "manifest.json").read_text())
    m["rig"]["mirror"]["offset"] += 1.0
    (work / "easy_s0" / "manifest.json").write_text(json.dumps(m))
    status = main(["experiment", "tracking", "--seeds", "0", *TINY, "--work", str(work), "--out",
                   str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert status == 1 and "easy_s0" in err and "rig" in err and not (tmp_path / "o").exists()


def test_killed_first_run_leaves_a_usable_folder(tmp_path):
    """A folder holding only a killed first run's temporary manifest is not "another dataset"."""
    import subprocess
    import sys

    from lipgen.experiments.tracking_inputs import TrackingSettings, _check_cache, dataset_settings

    gs = dataset_settings(TrackingSettings(preset="easy", frames=3, calib_frames=6), 0)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True, check=True).stdout.strip()
    (tmp_path / "easy_s0").mkdir()
    (tmp_path / "easy_s0" / f".manifest.json.tmp-{dead}-x").write_text("{")
    assert _check_cache(tmp_path / "easy_s0", gs) is False
    (tmp_path / "easy_s0" / "notes.txt").write_text("mine")
    with pytest.raises(Exception, match="no manifest.json"):
        _check_cache(tmp_path / "easy_s0", gs)


def test_lens_frames_are_passed_and_explained():
    from lipgen.experiments.tracking_inputs import TrackingSettings, dataset_settings

    assert dataset_settings(TrackingSettings(), 41).lens_frames == 30  # hard: the preset's
    assert dataset_settings(TrackingSettings(calib_frames=12), 41).lens_frames == 0
    assert dataset_settings(TrackingSettings(calib_frames=12, lens_frames=6), 41).lens_frames == 6


def test_read_only_work_is_refused_before_any_work(tmp_path, capsys, monkeypatch):
    """A --work that cannot be written (simulated: the tests may run as root) fails up front."""
    import os

    import lipgen.commands._output as output

    ro = tmp_path / "ro"
    ro.mkdir()
    access = os.access
    monkeypatch.setattr(output.os, "access", lambda p, mode: Path(p) != ro and access(p, mode))
    status = main(["experiment", "tracking", "--seeds", "0", *TINY, "--work", str(ro), "--out",
                   str(tmp_path / "out")])
    assert status == 1 and "not writable" in capsys.readouterr().err
    assert list(ro.iterdir()) == [] and not (tmp_path / "out").exists()


def test_existing_reconstruction_refused_from_python_too(tmp_path):
    """run_tracking's own check (not only the command's): an existing LABEL.recon.npz needs force."""
    from lipgen.experiments.tracking import run_tracking
    from lipgen.experiments.tracking_inputs import TrackingSettings, check_inputs

    s = TrackingSettings(preset="easy", seeds=(0,), frames=3, calib_frames=6)
    (tmp_path / "easy_s0.recon.npz").write_bytes(b"old")
    with pytest.raises(FileExistsError, match="easy_s0.recon.npz"):
        run_tracking(s, tmp_path, progress=False)
    assert (tmp_path / "easy_s0.recon.npz").read_bytes() == b"old"
    assert [label for label, _, _ in check_inputs(s, tmp_path, force=True)] == ["easy_s0"]


def test_a_set_that_cannot_be_reconstructed_is_reported_not_fatal(run, monkeypatch):
    """``hard`` 56 (a collapse: the nose never seen in both views) stopped the whole run with
    reconstruct's error after the sets before it; now it is reported, its visible sightings count
    as not accepted, and the other sets are scored as before."""
    import lipgen.recon.pipeline as pipeline

    root, first = run
    work = root / "out" / "work"
    real = pipeline.reconstruct_dataset

    def fails_on_s1(path, *a, **kw):
        if Path(path).name == "easy_s1":
            raise DatasetError(f"{path}: the nose mark was never seen in both views; cannot normalise")
        return real(path, *a, **kw)

    monkeypatch.setattr(pipeline, "reconstruct_dataset", fails_on_s1)
    out = root / "out_failed"
    assert main(["experiment", "tracking", "--datasets", str(work / "easy_s0"), str(work / "easy_s1"),
                 "--work", str(root / "work_failed"), "--out", str(out), "--no-progress"]) == 0
    got = json.loads((out / "tracking.json").read_text())
    s0, s1 = got["sets"]
    assert (s0["accepted"], s0["over_3px"]) == (first["sets"][0]["accepted"], first["sets"][0]["over_3px"])
    assert s1["not_reconstructed"]["reason"].endswith("cannot normalise")
    assert s1["visible"] == first["sets"][1]["visible"] and s1["accepted"] == 0 and s1["accepted_share"] == 0
    assert not any(s1["targets"].values()), "nothing accepted meets no target, not even none > 3 px"
    assert got["spread"]["rms_px"]["mean"] == pytest.approx(s0["rms_px"]), "over the reconstructed sets"
    pooled = got["pooled"]
    assert pooled["visible"] == s0["visible"] + s1["visible"] and pooled["accepted"] == s0["accepted"]
    assert pooled["not_reconstructed"] == ["easy_s1"]
    assert pooled["tracking_cpu_ms_per_frame"] == pytest.approx(s0["tracking_cpu_ms_per_frame"])
    md = (out / "tracking.md").read_text()
    assert "easy_s1 (not reconstructed)" in md and "**Not reconstructed** (1 of 2 sets" in md
    assert not (root / "work_failed" / "easy_s1.recon.npz").exists()
