"""``lipgen experiment tracking``: the tracker scored over generated sets against issue 15's targets.

One tiny run (preset easy, seeds 0 and 1, 6 frames, 6 calibration frames) is made once for the
module; its figures are checked against ``lipgen evaluate``'s tracking table on the same
reconstruction, also after sightings were moved and lost by hand (so that the > 3 px, rejected and
lost counts are not all zero), and a second run must reuse its datasets.
"""

import json
from dataclasses import replace

import numpy as np
import pytest

from lipgen.cli import main
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
    uv[0, 1:4, 2, 0] += 5.0       # virtual view: mark 2 of frames 1-3 moved 5 px in u
    uv[1, 0, :5, 1] += 3.5        # real view: marks 0-4 of frame 0 moved 3.5 px in v
    status[1, 4, 7] = 3           # real view: mark 7 of frame 4 lost
    damaged = replace(recon, uv=uv, status=status)
    file = root / "damaged.recon.npz"
    damaged.save(file)
    fig, errors = set_figures(work / "easy_s1", damaged)
    table = _evaluate_tracking(root, "easy_s1", file, "damaged")
    _check_against(fig, table)
    assert fig["over_3px"] == 3 + 5 and fig["lost"] >= 1
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


def test_rerun_reuses_the_datasets(run, monkeypatch):
    root, first = run
    raw = root / "out" / "work" / "easy_s0" / "raw" / "000000.png"
    stamp = raw.stat().st_mtime_ns

    def no_generation(*a, **k):
        raise AssertionError("generate called on a cached dataset")

    monkeypatch.setattr("lipgen.dataset.generate.generate", no_generation)
    out2 = root / "out2"
    assert main(["experiment", "tracking", "--seeds", "0", "1", *TINY, "--out", str(out2), "--work",
                 str(root / "out" / "work")]) == 0
    again = json.loads((out2 / "tracking.json").read_text())
    assert [s["reused"] for s in again["sets"]] == [True, True]
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
    assert status == 1 and "part: 1 frames are missing (e.g. frame 2)" in err
    assert not (tmp_path / "o").exists()
