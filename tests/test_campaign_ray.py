"""``lipgen campaign`` on an embedded local Ray with 2 CPUs (the slow set: Ray's start alone costs
about 10 s; ``make test`` runs the campaign's logic in-process, tests/test_campaign.py): one Ray for the
module, started without Ray's fixed 30 s window (so a loaded machine does not skip it); a worker
killed mid-task loses only its task, and the datasets are byte-identical to ``lipgen generate``.
"""

import os
import threading
import time
from pathlib import Path

import pytest

from lipgen.campaign import parse_plan, run_campaign

BASE = {"frames": 8, "size": "160x120", "calib_frames": 1, "script": "AA:0.2 OO:0.2 M F"}


def _files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


# --- running: Ray ----------------------------------------------------------------------------


def _ours(pid: int) -> bool:
    """Whether ``pid`` descends from this test process (only those are ever killed)."""
    me = os.getpid()
    while pid > 1:
        if pid == me:
            return True
        try:
            pid = int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            return False
    return False


def _kill_one_render_worker(runner) -> int | None:
    """SIGKILL the first of our Ray workers seen rendering a chunk (its title is set by Ray)."""
    import signal

    while runner.is_alive():
        for d in Path("/proc").glob("[0-9]*"):
            try:
                title = (d / "cmdline").read_bytes().split(b"\0")[0]
            except OSError:
                continue
            if title.startswith(b"ray::render_chunk") and _ours(int(d.name)):
                os.kill(int(d.name), signal.SIGKILL)
                return int(d.name)
        time.sleep(0.05)
    return None


@pytest.fixture(scope="module")
def ray_executor():
    """One embedded Ray with 2 CPUs for the module. Its start waits for the raylet as long as
    that lives (Ray's own fixed 30 s window is what a loaded machine missed), so no skip."""
    pytest.importorskip("ray")
    from lipgen.campaign import RayExecutor

    ex = RayExecutor(num_cpus=2, retries=1)
    yield ex
    ex.shutdown()


def test_the_embedded_start_waits_for_a_live_raylet_and_fails_for_a_dead_one(monkeypatch):
    import types

    from lipgen.campaign import executors

    calls = []

    def slow_registration(gcs, node):  # the node registers on the 4th look, as under load
        calls.append(node)
        if len(calls) < 4:
            raise RuntimeError("node info not available")
        return {"node_id": node}

    services = types.SimpleNamespace(get_node=slow_registration)
    ray = types.SimpleNamespace(_private=types.SimpleNamespace(services=services))
    monkeypatch.setattr(executors, "_raylet_alive", lambda: True)
    with executors._patient_node_start(ray, poll=0.0):
        assert services.get_node("gcs", "n1") == {"node_id": "n1"} and len(calls) == 4
    assert services.get_node is slow_registration  # put back
    calls.clear()
    monkeypatch.setattr(executors, "_raylet_alive", lambda: False)  # the raylet died: fail at once
    with executors._patient_node_start(ray, poll=0.0), pytest.raises(RuntimeError, match="not available"):
        services.get_node("gcs", "n1")
    assert len(calls) == 1
    assert executors._raylet_alive() is False  # no raylet child of this test process


@pytest.mark.render
@pytest.mark.slow(cover=("tests/test_campaign.py::test_a_small_inline_campaign_matches_generate_fails_one_item_and_resumes",
                         "tests/test_campaign.py::test_a_dead_local_worker_loses_only_its_own_task",
                         "tests/test_campaign_ray.py::test_the_embedded_start_waits_for_a_live_raylet_and_fails_for_a_dead_one"))
def test_a_ray_campaign_reruns_lost_work_and_is_byte_identical_to_generate(ray_executor, tmp_path):
    pytest.importorskip("lipgen.rig.render")
    from lipgen.dataset.generate import generate

    def crash_once(marker: str) -> int:  # nested, so Ray ships it by value
        if not os.path.exists(marker):
            Path(marker).write_text("crashed")
            os._exit(9)  # the worker dies mid-task, as under SIGKILL
        return os.getpid()

    h = ray_executor.submit(crash_once, str(tmp_path / "marker"))
    assert isinstance(ray_executor.result(h), int) and (tmp_path / "marker").is_file()
    env = ray_executor.result(ray_executor.submit(os.getenv, "OPENBLAS_NUM_THREADS"))
    assert env == "1" and ray_executor.result(ray_executor.submit(os.getenv, "LP_NUM_THREADS")) == "0"

    plan = parse_plan({"base": {**BASE, "frames": 6}, "campaign": {"stages": ["generate"], "chunk_frames": 2},
                       "grid": {"seed": [3, 5]}})
    result: dict = {}
    runner = threading.Thread(target=lambda: result.update(
        index=run_campaign(plan, tmp_path / "c", executor=ray_executor, progress=False)))
    runner.start()
    killed = _kill_one_render_worker(runner)  # SIGKILL a worker mid-chunk, when one is caught at it
    runner.join()
    index = result["index"]
    assert [e["status"] for e in index["items"]] == ["done", "done"], (killed, index)
    assert index["runs"][0]["executor"] == "ray" and index["runs"][0]["workers"] == 2
    for k, item in enumerate(plan.items):
        ref = generate(tmp_path / f"ref{k}", item.settings, progress=False)
        a, b = _files(ref), _files(tmp_path / "c" / "items" / item.name / "dataset")
        assert a.keys() == b.keys() and all(a[n] == b[n] for n in a), f"item {k} differs from generate"
