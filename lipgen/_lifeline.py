"""Worker processes that end with their parent.

A render worker holds an EGL context and ~240 MB; when the process that started it is killed
(SIGKILL, SIGTERM, a closed terminal) nothing else would stop it: it blocks forever on a task
queue whose other end it holds itself. :func:`die_with_parent` is called first thing in such a
worker. On Linux the kernel sends the worker a signal when its parent dies
(``PR_SET_PDEATHSIG``); everywhere, a daemon thread also polls the parent's pid, so the worker
ends within about ``poll_s`` seconds even where the signal is not available. When the workers
are gone, multiprocessing's resource tracker reads end-of-file on its pipe and exits too.
"""

from __future__ import annotations

import ctypes
import logging
import os
import signal
import sys
import threading
import time

__all__ = ["die_with_parent", "PR_SET_PDEATHSIG"]

log = logging.getLogger(__name__)

PR_SET_PDEATHSIG = 1
"""The prctl option that arms the parent-death signal (``<linux/prctl.h>``)."""


def _set_pdeathsig(sig: int) -> bool:
    """Ask the kernel to send ``sig`` to this process when its parent ends (Linux only)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0
    except (OSError, AttributeError):  # no libc symbol: the poll below still works
        return False


def _watch(parent_pid: int, poll_s: float) -> None:
    while os.getppid() == parent_pid:
        time.sleep(poll_s)
    log.warning("parent process %d is gone; worker %d exits", parent_pid, os.getpid())
    os._exit(128 + signal.SIGTERM)  # no clean-up: the parent that would want the result is dead


def die_with_parent(parent_pid: int, poll_s: float = 1.0, sig: int = signal.SIGTERM) -> bool:
    """Make the calling process end when process ``parent_pid`` (its parent) ends.

    Parameters
    ----------
    parent_pid : int
        The pid of the parent as the parent saw it (``os.getpid()`` there, before starting the
        worker): if the parent already died before this call, the process exits at once.
    poll_s : float
        Seconds between checks of the fallback watcher thread.
    sig : int
        Signal the kernel sends on the parent's death (Linux).

    Returns
    -------
    bool
        Whether the kernel's parent-death signal was armed (False: the poll alone watches).
    """
    if isinstance(parent_pid, bool) or not isinstance(parent_pid, int) or parent_pid <= 0:
        raise ValueError(f"parent_pid must be a positive process id, got {parent_pid!r}")
    if not poll_s > 0:
        raise ValueError(f"poll_s must be positive, got {poll_s!r}")
    armed = _set_pdeathsig(sig)
    if os.getppid() != parent_pid:  # the parent died before the signal was armed
        os._exit(128 + signal.SIGTERM)
    threading.Thread(target=_watch, args=(parent_pid, poll_s), daemon=True,
                     name="lipgen-lifeline").start()
    return armed
