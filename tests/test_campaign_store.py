"""Campaigns into an object store through fsspec (``lipgen.campaign.remote``), and the index as
``campaign.parquet``.

The store's rules are checked on fsspec's in-memory filesystem; a whole campaign runs into a
``file://`` URL (the same code path as ``s3://``: staged on the worker, uploaded file by file)
and must hold the very bytes ``lipgen generate`` writes.
"""

import json
from pathlib import Path

import pytest
from _campaign_inline import inline_executor

from lipgen.campaign import CampaignError, parse_plan, run_campaign
from lipgen.campaign.remote import Store, check_store, read_store_index, store_lock, write_store_index
from lipgen.campaign.run import _new_index
from lipgen.campaign.store import index_from_table, read_index, read_index_table, write_index

pytest.importorskip("fsspec")

BASE = {"frames": 8, "size": "160x120", "calib_frames": 1, "script": "AA:0.2 OO:0.2 M F"}
_PLAN = {"base": BASE, "campaign": {"stages": ["generate", "nrsfm"], "chunk_frames": 3},
         # item 1 has too few frames for NRSfM with K = 2: it must fail alone
         "items": [{"seed": 3, "frames": 10}, {"seed": 4, "frames": 2}]}


def _index_with_records():
    plan = parse_plan(_PLAN)
    index = _new_index(plan)
    index["items"][0]["status"] = "done"
    index["items"][0]["stages"]["generate"].update(status="done", seconds=3.5, task_seconds=2.25, chunks=4)
    index["items"][1]["stages"]["nrsfm"].update(status="failed", error="ValueError: K too large")
    return plan, index


def test_store_urls_that_cannot_work_are_refused_naming_them(tmp_path):
    with pytest.raises(CampaignError, match=r"'nosuch://x/y': unknown storage scheme 'nosuch'"):
        Store("nosuch://x/y")
    with pytest.raises(CampaignError, match="names no folder"):
        Store("memory://")
    plan = parse_plan({"base": BASE, "campaign": {"stages": ["generate"]}})
    with pytest.raises(CampaignError, match="memory:// lives in this process only"):
        run_campaign(plan, "memory://c1", executor="local", workers=1, progress=False)
    try:
        import s3fs  # noqa: F401
    except ImportError:
        with pytest.raises(CampaignError, match=r"s3:// scheme needs a package"):
            Store("s3://bucket/runs")
    (tmp_path / "f").write_text("x")
    with pytest.raises(CampaignError, match="is a file"):
        run_campaign(plan, f"file://{tmp_path}/f", executor="local", workers=1, progress=False)
    assert (tmp_path / "f").read_text() == "x"


def test_a_store_keeps_the_folder_rules_and_the_lock():
    import uuid

    plan, index = _index_with_records()
    where = f"memory://t-{uuid.uuid4().hex}/c"
    store = Store(where)
    assert check_store(store, plan.fingerprint(), resume=False) is None  # new
    store.write_bytes("notes.txt", b"mine")
    with pytest.raises(CampaignError, match="not a campaign"):
        check_store(store, plan.fingerprint(), resume=True)
    assert store.read_bytes("notes.txt") == b"mine"  # nothing deleted
    store.remove("notes.txt")
    write_store_index(store, index)
    assert store.files("") == {"campaign.json", "campaign.parquet"}
    with pytest.raises(CampaignError, match="--resume"):
        check_store(store, plan.fingerprint(), resume=False)
    with pytest.raises(CampaignError, match="another plan"):
        check_store(store, "0" * 16, resume=True)
    assert check_store(store, plan.fingerprint(), resume=True)["items"] == index["items"]
    assert read_store_index(store) == json.loads(json.dumps(index))
    with store_lock(store):
        with pytest.raises(CampaignError, match=f"another campaign is running into {where}"):
            with store_lock(store):
                pass
        assert store.isfile(".campaign.lock")
    assert not store.isfile(".campaign.lock")  # released at the end


def test_the_parquet_index_round_trips_to_the_json_index(tmp_path):
    import pyarrow.parquet as pq

    _, index = _index_with_records()
    write_index(tmp_path, index)
    table = read_index_table(tmp_path)
    assert table.num_rows == 2 and table.column("item").to_pylist() == ["0000", "0001"]
    assert table.column("status").to_pylist() == ["done", "pending"]
    assert table.column("seed").to_pylist() == [3, 4] and table.column("frames").to_pylist() == [10, 2]
    assert table.column("generate.seconds").to_pylist() == [3.5, None]
    assert table.column("nrsfm.error").to_pylist() == [None, "ValueError: K too large"]
    assert index_from_table(table) == read_index(tmp_path)
    # a plain parquet reader sees the same table
    assert pq.read_table(tmp_path / "campaign.parquet").column("generate.task_seconds").to_pylist()[0] == 2.25


def _store_files(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.mark.render
@pytest.mark.slow(cover=("tests/test_campaign_store.py::test_a_small_inline_campaign_into_a_file_url_matches_generate_and_resumes",
                         "tests/test_campaign.py::test_a_dead_local_worker_loses_only_its_own_task"))
def test_a_campaign_into_a_file_url_matches_generate_and_resumes(tmp_path, monkeypatch):
    pytest.importorskip("lipgen.rig.render")
    pytest.importorskip("pyarrow")
    from lipgen.campaign.aggregate import write_campaign_report
    from lipgen.dataset.generate import generate

    monkeypatch.setenv("LIPGEN_STAGING", str(tmp_path / "staging"))  # inherited by the workers
    plan = parse_plan(_PLAN)
    root = tmp_path / "bucket" / "runs" / "c"
    url = f"file://{root}"
    index = run_campaign(plan, url, executor="local", workers=2, progress=False)
    ok, bad = index["items"][0], index["items"][1]
    assert ok["status"] == "done" and bad["status"] == "failed", index["items"]
    assert "too large" in bad["stages"]["nrsfm"]["error"]
    nr = json.loads((root / "items/0000/nrsfm.json").read_text())  # a stage after generate, uploaded
    assert nr["truth_tracks"]["frames"] == 10
    assert index_from_table(read_index_table(root)) == read_index(root)
    ref = generate(tmp_path / "ref", plan.items[0].settings, progress=False)
    a, b = _store_files(ref), _store_files(root / "items/0000/dataset")
    assert a.keys() == b.keys() and all(a[k] == b[k] for k in a), "store dataset differs from generate"
    assert not list((tmp_path / "staging").rglob("*.png")), "frames were left in the staging folder"
    assert not (root / ".campaign.lock").exists()
    # a second run is refused without --resume; with it, a frame lost from the store is redone alone
    with pytest.raises(CampaignError, match="--resume"):
        run_campaign(plan, url, executor="local", workers=1, progress=False)
    before = {p: p.stat().st_mtime_ns for p in root.rglob("*") if p.is_file() and "0000" in p.parts}
    (root / "items/0001/dataset/truth/000001.npz").unlink()
    index = run_campaign(plan, url, executor="local", workers=2, resume=True, progress=False)
    after = {p: p.stat().st_mtime_ns for p in root.rglob("*") if p.is_file() and "0000" in p.parts}
    assert after == before, "a finished item was redone"
    assert (root / "items/0001/dataset/truth/000001.npz").is_file() and len(index["runs"]) == 2
    ref1 = generate(tmp_path / "ref1", plan.items[1].settings, progress=False)
    a, b = _store_files(ref1), _store_files(root / "items/0001/dataset")
    assert a.keys() == b.keys() and all(a[k] == b[k] for k in a), "resumed store dataset differs"
    # the report reads the store and is written into it
    md = write_campaign_report(url)
    assert md == f"{url}/report/report.md" and "## Failed items" in (root / "report/report.md").read_text()


@pytest.mark.render
def test_a_small_inline_campaign_into_a_file_url_matches_generate_and_resumes(tmp_path, monkeypatch):
    """The store's staging, upload and download on a small plan, its tasks run in this process."""
    pytest.importorskip("lipgen.rig.render")
    pytest.importorskip("pyarrow")
    from lipgen.campaign.aggregate import write_campaign_report
    from lipgen.dataset import generate as gen

    monkeypatch.setenv("LIPGEN_STAGING", str(tmp_path / "staging"))
    plan = parse_plan({**_PLAN, "base": {**BASE, "frames": 4},
                       "items": [{"seed": 3}, {"seed": 4, "frames": 2}],
                       "campaign": {"stages": ["generate", "nrsfm"], "chunk_frames": 2}})
    root = tmp_path / "bucket" / "runs" / "c"
    url = f"file://{root}"
    with inline_executor(monkeypatch) as ex:
        index = run_campaign(plan, url, executor=ex, progress=False)
        ok, bad = index["items"][0], index["items"][1]
        assert ok["status"] == "done" and bad["status"] == "failed", index["items"]
        assert "too large" in bad["stages"]["nrsfm"]["error"]
        nr = json.loads((root / "items/0000/nrsfm.json").read_text())  # a stage after generate, uploaded
        assert nr["truth_tracks"]["frames"] == 4
        assert index_from_table(read_index_table(root)) == read_index(root)
        assert not list((tmp_path / "staging").rglob("*.png")), "frames were left in the staging folder"
        assert not (root / ".campaign.lock").exists()
        with pytest.raises(CampaignError, match="--resume"):
            run_campaign(plan, url, executor=ex, progress=False)
        before = {p: p.stat().st_mtime_ns for p in root.rglob("*") if p.is_file() and "0000" in p.parts}
        (root / "items/0001/dataset/truth/000001.npz").unlink()
        index = run_campaign(plan, url, executor=ex, resume=True, progress=False)
        after = {p: p.stat().st_mtime_ns for p in root.rglob("*") if p.is_file() and "0000" in p.parts}
        assert after == before, "a finished item was redone"
        assert (root / "items/0001/dataset/truth/000001.npz").is_file() and len(index["runs"]) == 2
        gen._close_worker()  # the tasks' renderer, kept in this process as in a worker
    for k, item in enumerate(plan.items):
        ref = gen.generate(tmp_path / f"ref{k}", item.settings, progress=False)
        a, b = _store_files(ref), _store_files(root / "items" / item.name / "dataset")
        assert a.keys() == b.keys() and all(a[n] == b[n] for n in a), f"store item {k} differs from generate"
    md = write_campaign_report(url)
    assert md == f"{url}/report/report.md" and "## Failed items" in (root / "report/report.md").read_text()
