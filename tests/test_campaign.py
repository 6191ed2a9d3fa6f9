"""``lipgen campaign``: plan checks, the folder rules, the local executor path end to end, and
(when ray is installed) a small campaign on an embedded local Ray with 2 CPUs.

The datasets are tiny (160x120, a few frames); a campaign's dataset must be byte-identical to
``lipgen generate`` with the same settings, however its frames were split between workers.
"""

import json
import os
import time
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

import numpy as np
import pytest
from _campaign_inline import inline_executor

from lipgen.campaign import (
    CampaignError,
    ClusterError,
    LocalExecutor,
    PlanError,
    check_address,
    load_plan,
    parse_plan,
    read_index,
    run_campaign,
)
from lipgen.campaign.aggregate import interval, write_campaign_report
from lipgen.campaign.store import campaign_lock
from lipgen.cli import main
from lipgen.dataset import GenerateSettings

BASE = {"frames": 8, "size": "160x120", "calib_frames": 1, "script": "AA:0.2 OO:0.2 M F"}


def _files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


# --- the plan -------------------------------------------------------------------------------


def test_a_plan_expands_to_items_in_a_fixed_order():
    plan = parse_plan({"base": BASE, "grid": {"seed": [0, 1], "noise": [0.5, 2.0]},
                       "items": [{"head_rotation_deg": 2.0}, {"head_rotation_deg": 6.0}],
                       "train": {"modes": 3}, "campaign": {"chunk_frames": 3}})
    assert len(plan.items) == 8 and plan.chunk_frames == 3
    assert plan.swept_keys == ("seed", "noise", "head_rotation_deg")
    first = plan.items[0].settings
    assert first == GenerateSettings(frames=8, size=(160, 120), calib_frames=1, script=BASE["script"], seed=0,
                                     noise=0.5, head_rotation_deg=2.0)
    assert [it.swept["noise"] for it in plan.items[:4]] == [0.5, 2.0, 0.5, 2.0]
    assert plan.items[4].swept["head_rotation_deg"] == 6.0
    assert plan.stages == ("generate", "reconstruct", "train", "evaluate", "nrsfm")
    # the stored form reads back to the same plan, and its fingerprint is stable
    again = parse_plan(plan.to_dict())
    assert [it.settings for it in again.items] == [it.settings for it in plan.items]
    assert again.fingerprint() == plan.fingerprint()
    other = parse_plan({"base": {**BASE, "seed": 9}, "train": {"modes": 3}})
    assert other.fingerprint() != plan.fingerprint()


@pytest.mark.parametrize("raw, match", [
    ({"base": BASE, "grid": {"sed": [1, 2]}}, r"unknown key\(s\) \['sed'\] in \[grid\]"),
    ({"base": {**BASE, "colour": 1}}, r"'colour'.*\[base\]"),
    ({"base": BASE, "items": [{"nois": 1}]}, r"'nois'.*\[\[items\]\] #0"),
    ({"base": BASE, "extra": {}}, r"'extra'.*top level"),
    ({"base": BASE, "campaign": {"stage": ["generate"]}}, r"'stage'.*\[campaign\]"),
    ({"base": BASE, "grid": {"seed": []}}, r"\[grid\] seed is an empty list"),
    ({"base": BASE, "items": []}, "empty list"),
    ({"base": BASE, "grid": {"seed": 3}}, r"\[grid\] seed must be a list"),
    ({"base": BASE, "grid": {"noise": [1.0, -1.0]}}, r"item 1 \(noise=-1.0\).*noise must be in"),
    ({"base": {**BASE, "size": "641x480"}}, "4:3"),
    ({"base": {**BASE, "script": "AA ZZ"}}, "ZZ"),
    ({"base": BASE, "campaign": {"stages": ["train"]}}, r"'train' needs \['reconstruct'\]"),
    ({"base": BASE, "campaign": {"stages": ["generate", "render"]}}, r"unknown stage\(s\) \['render'\]"),
    ({"base": BASE, "campaign": {"chunk_frames": 0}}, r"chunk_frames must be a whole number"),
    ({"base": BASE, "grid": {"seed": [1]}, "items": [{"seed": 2}]}, r"\['seed'\] are both in \[grid\]"),
    ({"base": BASE}, r"modes = 10 needs at least 11 training frames"),
    ({"base": BASE, "train": {"modes": 3}, "nrsfm": {"method": "magic"}}, r"\[nrsfm\] method"),
    ({"base": BASE, "train": {"modes": "3"}}, r"\[train\] modes must be a int"),
    ({"base": BASE, "train": {"modes": 3}, "reconstruct": {"normalisation": "none"}}, "normalisation"),
])
def test_a_bad_plan_is_refused_naming_the_key(raw, match):
    with pytest.raises(PlanError, match=match):
        parse_plan(raw)


def test_a_plan_file_that_is_not_toml_is_refused(tmp_path):
    bad = tmp_path / "plan.toml"
    bad.write_text("[base\nframes = 3\n")
    with pytest.raises(PlanError, match="not valid TOML"):
        load_plan(bad)
    with pytest.raises(PlanError, match="does not exist"):
        load_plan(tmp_path / "nope.toml")


def test_the_interval_is_the_student_t_interval():
    from scipy import stats

    x = np.array([1.0, 2.5, 2.0, 4.0, 3.1])
    m, lo, hi, n = interval(x)
    want = stats.t.interval(0.95, len(x) - 1, loc=x.mean(), scale=stats.sem(x))
    assert n == 5 and m == pytest.approx(x.mean()) and (lo, hi) == pytest.approx(want)
    assert interval([2.0, None, float("nan")])[3] == 1 and np.isnan(interval([2.0])[1])
    assert interval([])[3] == 0


# --- the folder -----------------------------------------------------------------------------


def test_a_folder_holding_something_else_is_refused_and_kept(tmp_path):
    plan = parse_plan({"base": BASE, "campaign": {"stages": ["generate"]}})
    out = tmp_path / "c"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    with pytest.raises(CampaignError, match="not a campaign folder"):
        run_campaign(plan, out, executor="local", workers=1, progress=False)
    assert [p.name for p in out.iterdir()] == ["notes.txt"] and (out / "notes.txt").read_text() == "mine"
    file = tmp_path / "f"
    file.write_text("x")
    with pytest.raises(CampaignError, match="is a file"):
        run_campaign(plan, file, executor="local", progress=False)


def test_a_second_campaign_into_a_folder_is_refused_by_the_lock(tmp_path):
    with campaign_lock(tmp_path):
        with pytest.raises(CampaignError, match="another campaign is running"):
            with campaign_lock(tmp_path):
                pass
    with campaign_lock(tmp_path):  # released when the holder ends
        pass


def test_an_unreachable_address_fails_fast_and_writes_nothing(tmp_path, monkeypatch):
    import lipgen.campaign.run as run_module

    def _no_executor(*args, **kwargs):  # "fast": refused by the address check, before Ray is started
        raise AssertionError("an executor was made for an unreachable address")

    monkeypatch.setattr(run_module, "make_executor", _no_executor)
    plan = parse_plan({"base": BASE, "campaign": {"stages": ["generate"]}})
    with pytest.raises(ClusterError, match="cannot reach the Ray cluster at 127.0.0.1:1"):
        run_campaign(plan, tmp_path / "c", address="127.0.0.1:1", progress=False)
    assert not (tmp_path / "c").exists()
    with pytest.raises(ClusterError, match="HOST:PORT"):
        check_address("nohostport")
    assert main(["campaign", "x.toml", "--out", str(tmp_path / "d"), "--address", "127.0.0.1:1"]) == 1


def _crash_once(marker: str) -> int:
    """Kill this worker on the first call (as a SIGKILL would), succeed on the next."""
    if not os.path.exists(marker):
        Path(marker).write_text("crashed")
        os._exit(9)
    return os.getpid()


def test_the_local_executor_reruns_a_task_whose_worker_died(tmp_path):
    ex = LocalExecutor(workers=1, retries=1)
    try:
        h = ex.submit(_crash_once, str(tmp_path / "marker"))
        assert isinstance(ex.result(h), int) and h.attempts == 2  # result() waits, however long
        assert ex.wait([h]) == [h]
        assert ex.result(ex.submit(os.getenv, "OPENBLAS_NUM_THREADS")) == "1"
    finally:
        ex.shutdown()


def _crash_when(started: str, marker: str) -> int:
    """Once ``started`` exists (a sibling task is running), die as under SIGKILL (first call);
    the rerun says so in ``marker + ".rerun"``."""
    if os.path.exists(marker):
        Path(marker + ".rerun").write_text("rerun")
    while not os.path.exists(started):
        time.sleep(0.01)
    return _crash_once(marker)


def _sibling(started: str, marker: str) -> int:
    """Count its runs in ``started``; stay running until the crashed task was run again, i.e. until
    the driver has learnt of its sibling's death (an event, however loaded the machine)."""
    with open(started, "a") as fh:
        fh.write("run\n")
    while not os.path.exists(marker + ".rerun"):
        time.sleep(0.01)
    return os.getpid()


def test_a_dead_local_worker_loses_only_its_own_task(tmp_path):
    started, marker = str(tmp_path / "started"), str(tmp_path / "marker")
    ex = LocalExecutor(workers=2, retries=1)
    try:
        crash, sibling = ex.submit(_crash_when, started, marker), ex.submit(_sibling, started, marker)
        pids = {ex.result(crash), ex.result(sibling)}
        assert crash.attempts == 2 and sibling.attempts == 1 and ex.lost == 1
        assert Path(started).read_text() == "run\n", "the sibling task was run again"
        assert len(pids) == 2
        # a task that kills its worker every time ends with the pool's error after its retries
        doomed = ex.submit(os._exit, 3)
        with pytest.raises(BrokenProcessPool):
            ex.result(doomed)
        assert doomed.attempts == 2 and ex.result(ex.submit(os.getenv, "LP_NUM_THREADS")) == "0"
    finally:
        ex.shutdown()


# --- running: the local executor path (rendering) --------------------------------------------

_GEN_NRSFM = {"base": BASE, "campaign": {"stages": ["generate", "nrsfm"], "chunk_frames": 3},
              # item 1 has too few frames for NRSfM with K = 2: it must fail alone
              "items": [{"seed": 3, "frames": 10}, {"seed": 4, "frames": 2}]}


@pytest.mark.render
@pytest.mark.slow(cover=("tests/test_campaign.py::test_a_small_inline_campaign_matches_generate_fails_one_item_and_resumes",
                         "tests/test_campaign.py::test_a_dead_local_worker_loses_only_its_own_task"))
def test_a_local_campaign_matches_generate_fails_one_item_and_resumes(tmp_path):
    pytest.importorskip("lipgen.rig.render")
    from lipgen.dataset.generate import generate

    plan = parse_plan(_GEN_NRSFM)
    out = tmp_path / "c"
    index = run_campaign(plan, out, executor="local", workers=2, progress=False)
    ok, bad = index["items"]
    errors = {e["name"]: {n: st.get("error") for n, st in e["stages"].items()} for e in index["items"]}
    assert ok["status"] == "done" and bad["status"] == "failed", errors
    assert bad["stages"]["generate"]["status"] == "done" and bad["stages"]["nrsfm"]["status"] == "failed"
    assert "too large" in bad["stages"]["nrsfm"]["error"]
    assert ok["stages"]["generate"]["chunks"] == 4  # 11 files in chunks of 3
    assert ok["stages"]["generate"]["peak_rss_mib"] > 0 and ok["stages"]["nrsfm"]["seconds"] > 0
    assert index["versions"]["lipgen"] and read_index(out)["fingerprint"] == plan.fingerprint()
    nr = json.loads((out / "items/0000/nrsfm.json").read_text())
    assert np.isfinite(nr["truth_tracks"]["e3d"]) and nr["truth_tracks"]["frames"] == 10
    ref = generate(tmp_path / "ref", plan.items[0].settings, progress=False)
    a, b = _files(ref), _files(out / "items/0000/dataset")
    assert a.keys() == b.keys() and all(a[k] == b[k] for k in a), "campaign dataset differs from generate"
    # the report lists the failed item
    report = write_campaign_report(out).read_text()
    assert "## Failed items" in report and "| 0001 |" in report and "too large" in report
    # a second run into the folder is refused without --resume; with it, only unfinished work is done
    with pytest.raises(CampaignError, match="--resume"):
        run_campaign(plan, out, executor="local", progress=False)
    other = parse_plan({**_GEN_NRSFM, "base": {**BASE, "noise": 2.0}})
    with pytest.raises(CampaignError, match="another plan"):
        run_campaign(other, out, executor="local", resume=True, progress=False)
    before = {p: p.stat().st_mtime_ns for p in (out / "items/0000").rglob("*") if p.is_file()}
    (out / "items/0001/dataset/truth/000001.npz").unlink()  # a frame lost: resume renders it again
    index = run_campaign(plan, out, executor="local", workers=2, resume=True, progress=False)
    after = {p: p.stat().st_mtime_ns for p in (out / "items/0000").rglob("*") if p.is_file()}
    assert after == before, "a finished item was redone"
    assert index["items"][1]["status"] == "failed" and (out / "items/0001/dataset/truth/000001.npz").is_file()
    assert len(index["runs"]) == 2


@pytest.mark.render
def test_a_worker_reuses_its_renderer_for_the_next_dataset_with_the_same_bytes(tmp_path):
    pytest.importorskip("lipgen.rig.render")
    from lipgen.campaign.stages import prepare, render_chunk
    from lipgen.dataset import generate as gen

    a, b = (GenerateSettings(frames=2, size=(160, 120), calib_frames=1, seed=k, noise=1.0) for k in (1, 2))
    for name, s in (("a", a), ("b", b)):
        ctx, jobs, _ = prepare(str(tmp_path / name), s.to_dict())
        renderer = gen._WORKER.get("renderer")
        render_chunk(ctx, jobs)
    assert renderer is not None and gen._WORKER["renderer"] is renderer, "the renderer was not kept"
    gen._close_worker()
    ref = gen.generate(tmp_path / "ref", b, progress=False)
    x, y = _files(ref), _files(tmp_path / "b")
    assert x.keys() == y.keys() and all(x[k] == y[k] for k in x), "a reused renderer changed the bytes"


_SMALL = {"base": {**BASE, "frames": 4}, "campaign": {"stages": ["generate", "nrsfm"], "chunk_frames": 2},
          # item 1 has too few frames for NRSfM with K = 2: it must fail alone
          "items": [{"seed": 3}, {"seed": 4, "frames": 2}]}


@pytest.fixture
def inline_campaign(monkeypatch):
    pytest.importorskip("lipgen.rig.render")
    with inline_executor(monkeypatch) as ex:
        yield ex


@pytest.mark.render
def test_a_small_inline_campaign_matches_generate_fails_one_item_and_resumes(tmp_path, inline_campaign):
    from lipgen.dataset import generate as gen
    from lipgen.dataset.generate import generate

    plan = parse_plan(_SMALL)
    out = tmp_path / "c"
    index = run_campaign(plan, out, executor=inline_campaign, progress=False)
    ok, bad = index["items"]
    assert ok["status"] == "done" and bad["status"] == "failed", index["items"]
    assert bad["stages"]["generate"]["status"] == "done" and bad["stages"]["nrsfm"]["status"] == "failed"
    assert "too large" in bad["stages"]["nrsfm"]["error"]
    assert ok["stages"]["generate"]["chunks"] == 3  # 5 files in chunks of 2
    assert ok["stages"]["generate"]["peak_rss_mib"] > 0 and ok["stages"]["nrsfm"]["seconds"] > 0
    assert index["versions"]["lipgen"] and index["runs"][0]["executor"] == "inline"
    assert read_index(out)["fingerprint"] == plan.fingerprint()
    nr = json.loads((out / "items/0000/nrsfm.json").read_text())
    assert np.isfinite(nr["truth_tracks"]["e3d"]) and nr["truth_tracks"]["frames"] == 4
    gen._close_worker()  # the tasks' renderer, kept in this process as in a worker
    ref = generate(tmp_path / "ref", plan.items[0].settings, progress=False)
    a, b = _files(ref), _files(out / "items/0000/dataset")
    assert a.keys() == b.keys() and all(a[k] == b[k] for k in a), "campaign dataset differs from generate"
    report = write_campaign_report(out).read_text()
    assert "## Failed items" in report and "| 0001 |" in report and "too large" in report
    with pytest.raises(CampaignError, match="--resume"):
        run_campaign(plan, out, executor=inline_campaign, progress=False)
    other = parse_plan({**_SMALL, "base": {**_SMALL["base"], "noise": 2.0}})
    with pytest.raises(CampaignError, match="another plan"):
        run_campaign(other, out, executor=inline_campaign, resume=True, progress=False)
    before = {p: p.stat().st_mtime_ns for p in (out / "items/0000").rglob("*") if p.is_file()}
    lost = out / "items/0001/dataset/truth/000001.npz"
    lost.unlink()  # a frame lost: resume renders it again
    index = run_campaign(plan, out, executor=inline_campaign, resume=True, progress=False)
    after = {p: p.stat().st_mtime_ns for p in (out / "items/0000").rglob("*") if p.is_file()}
    assert after == before, "a finished item was redone"
    assert index["items"][1]["status"] == "failed" and lost.is_file() and len(index["runs"]) == 2


# --- documentation that runs ------------------------------------------------------------------

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "campaign"


def test_the_example_plan_and_cluster_file_are_valid():
    plan = load_plan(EXAMPLES / "plan.toml")
    assert len(plan.items) == 30 and plan.swept_keys == ("seed", "noise", "head_rotation_deg")
    yaml = pytest.importorskip("yaml")
    cluster = yaml.safe_load((EXAMPLES / "cluster.yaml").read_text())
    keys = {"cluster_name", "provider", "available_node_types", "head_node_type", "setup_commands"}
    assert keys <= set(cluster)
    assert cluster["head_node_type"] in cluster["available_node_types"]
    assert any("libegl1" in c for c in cluster["setup_commands"])


def test_campaign_help_and_bad_command_lines(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["campaign", "--help"])
    text = capsys.readouterr().out
    assert "lipgen campaign report" in text and "--address" in text and "[grid]" in text
    assert main(["campaign", "report"]) == 1
    assert "needs the campaign folder" in capsys.readouterr().err
    assert main(["campaign", str(EXAMPLES / "plan.toml")]) == 1
    assert "--out DIR is required" in capsys.readouterr().err
    assert main(["campaign", "report", str(tmp_path)]) == 1
    assert "not a campaign folder" in capsys.readouterr().err


def _fake_campaign(root: Path) -> dict:
    """A campaign folder written by hand: 2 noise levels x 3 seeds, one item failed."""
    from lipgen.campaign.store import FORMAT, SCHEMA, write_index

    rng = np.random.default_rng(0)
    items, truth = [], {}
    for k, (noise, seed) in enumerate((n, s) for n in (0.5, 2.0) for s in (0, 1, 2)):
        name = f"{k:04d}"
        failed = k == 5
        items.append({"name": name, "swept": {"seed": seed, "noise": noise}, "settings": {},
                      "status": "failed" if failed else "done",
                      "stages": {"generate": {"status": "done", "seconds": 3.0 + k, "task_seconds": 2.0 + k},
                                 "evaluate": {"status": "failed" if failed else "done", "task_seconds": 1.0,
                                              "error": "ValueError: boom" if failed else None}}})
        if failed:
            continue
        tri = float(noise * 0.1 + rng.random() * 0.01)
        truth.setdefault(noise, []).append(tri)
        cell = {"vs_reach": tri, "vs_truth": 2 * tri}
        rep = {"tracking": {"virtual": {"rms_px": noise}, "real": {"rms_px": noise}},
               "triangulation": {"rms_mm": tri}, "normalisation": {"rms_mm": 0.5},
               "fields": {"rms_mm_vs_truth": 1.0},
               "table51": {row: {"10 modes": cell, "physics (reach)": cell}
                           for row in ("xyz (8 points)", "yz (all points)", "xy (all points)")}}
        (root / "items" / name / "report").mkdir(parents=True)
        (root / "items" / name / "report" / "report.json").write_text(json.dumps(rep))
        (root / "items" / name / "nrsfm.json").write_text(json.dumps({"truth_tracks": {"e3d": 0.3}}))
    write_index(root, {"format": FORMAT, "schema_version": SCHEMA, "name": "fake",
                       "swept_keys": ["seed", "noise"], "items": items})
    return truth


def test_the_report_aggregates_over_subjects_per_condition(tmp_path):
    from scipy import stats

    truth = _fake_campaign(tmp_path)
    md = write_campaign_report(tmp_path).read_text()
    rep = json.loads((tmp_path / "report" / "report.json").read_text())
    conds = {c["condition"]["noise"]: c for c in rep["conditions"]}
    assert set(conds) == {0.5, 2.0} and conds[0.5]["items"] == 3
    for noise, values in truth.items():
        got = conds[noise]["metrics"]["triangulation_mm"]
        lo, hi = stats.t.interval(0.95, len(values) - 1, loc=np.mean(values), scale=stats.sem(values))
        assert got["n"] == len(values) and got["mean"] == pytest.approx(np.mean(values))
        assert (got["lo95"], got["hi95"]) == pytest.approx((lo, hi))
    assert conds[2.0]["metrics"]["triangulation_mm"]["n"] == 2  # the failed item has no figures
    assert "### noise=0.5" in md and "| 0005 |" in md and "ValueError: boom" in md
    assert "![vs_noise.png](vs_noise.png)" in md and (tmp_path / "report" / "vs_noise.png").stat().st_size > 0
    slow = md.split("## Slowest items")[1]
    assert slow.index("| 0005 |") < slow.index("| 0004 |")  # most work first


def test_the_cluster_model_is_waves_of_slots_plus_serial_scheduling():
    from lipgen.bench import available_suites
    from lipgen.bench.campaign import predict

    assert "campaign" in available_suites()
    # 1000 items on 100 x 2 slots: 5 waves of 10 s at efficiency 0.5, plus start and 1000 x 3 submits
    assert predict(1000, 100, 2, 10.0, 0.5, 20.0, 0.001, 3) == pytest.approx(20 + 5 * 20 + 3.0)
    assert predict(1, 100, 2, 10.0, 1.0, 0.0, 0.0, 1) == pytest.approx(10.0)  # one item: one wave


def test_the_bench_reads_a_childs_cpu_time_from_proc():
    import subprocess
    import sys

    from lipgen.bench.campaign import _cpu_split, _descendants_cpu

    code = ("import time, sys\nt = time.process_time()\nwhile time.process_time() - t < 0.3: pass\n"
            "print(time.process_time(), flush=True)\nsys.stdin.read()")
    child = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                             text=True)
    try:
        own = float(child.stdout.readline())  # the child's own count, once it has burnt 0.3 s
        seen = _descendants_cpu()
        assert child.pid in seen
        assert seen[child.pid][1] == pytest.approx(own, abs=0.05)  # /proc ticks are 10 ms
        split = _cpu_split("local", {}, {child.pid: seen[child.pid]}, 0.1)
        assert split == {"workers_s": seen[child.pid][1], "ray_system_s": 0.0, "driver_s": 0.1}
        ray = _cpu_split("ray", {}, {1: ("ray::render_chunk", 2.0), 2: ("raylet", 0.5),
                                     3: ("ray::DashboardAgent", 0.25)}, 0.0)
        assert ray["workers_s"] == 2.0 and ray["ray_system_s"] == 0.75
    finally:
        child.communicate("")


def test_the_embedded_ray_node_skips_its_bookkeeping_unless_the_dashboard_is_asked_for(monkeypatch):
    from lipgen.campaign.executors import _QUIET_NODE, _node_env

    monkeypatch.delenv("RAY_event_stats", raising=False)
    monkeypatch.setenv("RAY_USAGE_STATS_ENABLED", "1")  # the user's own choice is kept
    quiet, full = _node_env(False), _node_env(True)
    assert quiet["RAY_enable_metrics_collection"] == "0" and quiet["RAY_event_stats"] == "0"
    assert quiet["RAY_USAGE_STATS_ENABLED"] == "1"
    assert not set(_QUIET_NODE) & set(full)
    assert quiet["OMP_NUM_THREADS"] == full["OMP_NUM_THREADS"] == "1"
