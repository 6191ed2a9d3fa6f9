"""Workers end with their parent: killing ``lipgen generate --workers 2`` leaves no orphans.

Real processes are killed with real signals. No check has a wall-clock limit that a loaded
machine could miss: each waits for an event (a pipe's end of file, a process's exit seen through
its pidfd, ``generate`` writing its frames or ending by itself). A process that outlived its
parent says so on stdout, or is found alive once every process it should follow has ended.
"""

import os
import select
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from lipgen._lifeline import die_with_parent


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


def _pidfds(pids) -> dict[int, int]:
    """A pidfd for each process still there (readable once it has ended)."""
    fds = {}
    for p in pids:
        try:
            fds[p] = os.pidfd_open(p)
        except ProcessLookupError:  # already gone and reaped
            pass
    return fds


# Only stops a hang if a regression leaves a worker alive for good: ~1000x the time the workers take
# to end at load 40, like ``give_up_s`` of the campaign executor's patient node start.
HANG_GUARD_S = 1800.0


def _wait_ended(fds: dict[int, int]) -> list[int]:
    """Wait until every process of ``fds`` has ended (an event: its pidfd turns readable); close
    the fds. Returns the pids still alive, which is only non-empty after the hang guard."""
    left = dict(fds)
    end = time.monotonic() + HANG_GUARD_S
    try:
        while left and time.monotonic() < end:
            ready, _, _ = select.select(list(left.values()), [], [], max(0.0, end - time.monotonic()))
            left = {p: fd for p, fd in left.items() if fd not in ready}
        return sorted(left)
    finally:
        for fd in fds.values():
            os.close(fd)


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
        "time.sleep(600); print('outlived its parent', flush=True)", str(os.getpid()), sys.argv[1]],
        stdout=sys.stdout)
    time.sleep(600)
""")


@pytest.mark.skipif(not hasattr(os, "pidfd_open"), reason="needs os.pidfd_open (Linux 5.3, Python 3.9)")
@pytest.mark.parametrize("poll_s", [0.2, 1000.0])  # 1000: the kernel's signal alone must do it
def test_a_worker_ends_when_its_parent_is_killed(tmp_path, poll_s):
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    parent = subprocess.Popen([sys.executable, "-c", _TREE, str(poll_s)], stdout=subprocess.PIPE, env=env,
                              start_new_session=True)
    kids: list[int] = []
    try:
        assert parent.stdout.readline().strip() == b"armed"
        kids = _children(parent.pid)
        assert len(kids) == 1
        fds = _pidfds(kids)
        parent.kill()
        parent.wait()
        # end of file once the worker (the pipe's last writer) has ended: at once, or after its
        # 600 s sleep with a line saying it outlived its parent
        said = parent.stdout.read()
        assert _wait_ended(fds) == [] and b"outlived" not in said, "the worker outlived its killed parent"
    finally:
        _reap([parent.pid, *kids])


@pytest.mark.render
@pytest.mark.skipif(not hasattr(os, "pidfd_open"), reason="needs os.pidfd_open (Linux 5.3, Python 3.9)")
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGINT], ids=lambda s: s.name)
def test_killing_generate_ends_its_workers_and_resource_tracker(tmp_path, sig):
    _kill_generate(tmp_path, sig)


@pytest.mark.render
@pytest.mark.skipif(not hasattr(os, "pidfd_open"), reason="needs os.pidfd_open (Linux 5.3, Python 3.9)")
@pytest.mark.slow(cover="tests/test_lifeline.py::test_killing_generate_ends_its_workers_and_resource_tracker[SIGKILL]")
def test_killing_generate_with_sigterm_ends_its_workers_and_resource_tracker(tmp_path):
    """SIGTERM ends ``generate`` as SIGKILL does (Python keeps the default action: no handler
    runs), so its workers see the same parent death as in the SIGKILL case."""
    _kill_generate(tmp_path, signal.SIGTERM)


def _kill_generate(tmp_path, sig) -> None:
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
        # no time limit: generate either starts its workers at work or ends by itself (400 frames)
        while proc.poll() is None:
            kids = _children(proc.pid)
            # two render workers and the resource tracker, and the workers at work
            if len(kids) >= 3 and len(list((out / "truth").glob("[0-9]*.npz"))) >= 2:
                break
            time.sleep(0.05)
        if proc.poll() is not None:
            pytest.fail(f"generate ended before it could be killed: {proc.stderr.read().decode()[-2000:]}")
        kids = _children(proc.pid)
        assert len(kids) >= 3, kids
        fds = _pidfds(kids)
        os.kill(proc.pid, sig)
        proc.wait()  # ends by the signal (SIGINT: at the next frame), or with its last frame
        assert len(list((out / "truth").glob("[0-9]*.npz"))) < 400, f"generate ran on after {sig.name}"
        assert _wait_ended(fds) == [], f"processes outlived generate after signal {sig.name}"
    finally:
        _reap([proc.pid, *kids])
