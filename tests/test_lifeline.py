"""Workers end with their parent: killing ``lipgen generate --workers 2`` leaves no orphans.

Real processes are killed with real signals; the checks poll with a generous bound (the
workers end within about a second on an idle machine), so a loaded machine only makes them
slower, never wrong.
"""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from lipgen._lifeline import die_with_parent

BOUND_S = 60.0


def _children(pid: int) -> list[int]:
    kids = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            kids += [int(k) for k in (task / "children").read_text().split()]
        except OSError:
            pass
    return kids


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state not in ("Z", "X")  # a zombie has ended; only its exit status is left


def _wait_gone(pids, bound=BOUND_S) -> list[int]:
    deadline = time.monotonic() + bound
    while time.monotonic() < deadline:
        left = [p for p in pids if _alive(p)]
        if not left:
            return []
        time.sleep(0.1)
    return [p for p in pids if _alive(p)]


def _reap(pids) -> None:
    for p in pids:  # only processes this test started
        if _alive(p):
            os.kill(p, signal.SIGKILL)


pytestmark = pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="needs Linux /proc")


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match="parent_pid"):
        die_with_parent(0)
    with pytest.raises(ValueError, match="parent_pid"):
        die_with_parent(True)
    with pytest.raises(ValueError, match="poll_s"):
        die_with_parent(os.getppid(), poll_s=0)


_TREE = textwrap.dedent("""
    import os, subprocess, sys, time
    child = subprocess.Popen([sys.executable, "-c",
        "import os, sys, time; from lipgen._lifeline import die_with_parent; "
        "die_with_parent(int(sys.argv[1]), poll_s=float(sys.argv[2])); print('armed', flush=True); "
        "time.sleep(600)", str(os.getpid()), sys.argv[1]], stdout=sys.stdout)
    time.sleep(600)
""")


@pytest.mark.parametrize("poll_s", [0.2, 1000.0])  # 1000: the kernel's signal alone must do it
def test_a_worker_ends_when_its_parent_is_killed(tmp_path, poll_s):
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    parent = subprocess.Popen([sys.executable, "-c", _TREE, str(poll_s)], stdout=subprocess.PIPE, env=env,
                              start_new_session=True)
    try:
        assert parent.stdout.readline().strip() == b"armed"
        kids = _children(parent.pid)
        assert len(kids) == 1
        parent.kill()
        parent.wait()
        assert _wait_gone(kids) == [], "the worker outlived its killed parent"
    finally:
        _reap([parent.pid, *_children(parent.pid)])


@pytest.mark.render
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM, signal.SIGINT], ids=lambda s: s.name)
def test_killing_generate_ends_its_workers_and_resource_tracker(tmp_path, sig):
    pytest.importorskip("lipgen.rig.render")
    out = tmp_path / "ds"
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]), OMP_NUM_THREADS="1",
               OPENBLAS_NUM_THREADS="1")
    args = [sys.executable, "-m", "lipgen", "generate", "--out", str(out), "--frames", "400", "--seed", "1",
            "--size", "160x120", "--calib-frames", "0", "--workers", "2", "--no-progress"]
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env,
                            start_new_session=True)
    kids: list[int] = []
    try:
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and proc.poll() is None:
            kids = _children(proc.pid)
            # two render workers and the resource tracker, and the workers at work
            if len(kids) >= 3 and len(list((out / "truth").glob("[0-9]*.npz"))) >= 2:
                break
            time.sleep(0.05)
        if proc.poll() is not None:
            pytest.fail(f"generate ended before it could be killed: {proc.stderr.read().decode()[-2000:]}")
        kids = _children(proc.pid)
        assert len(kids) >= 3, kids
        os.kill(proc.pid, sig)
        proc.wait(timeout=BOUND_S)
        assert _wait_gone(kids) == [], f"processes outlived generate after signal {sig.name}"
    finally:
        _reap([proc.pid, *kids])
