"""The local executor: a campaign's tasks on processes of this machine.

Each worker is its own one-process pool, and a task goes to a worker only when that worker is
free (the queue is kept here, in the driver). So when a worker dies (SIGKILL, the OOM killer, a
crash in the GL driver) the only task lost is the one it was running: that task is submitted
again (``retries`` times) on a new process, and the tasks of the other workers run on untouched.
"""

from __future__ import annotations

import collections
import logging
import multiprocessing
import os
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor
from concurrent.futures import wait as futures_wait
from concurrent.futures.process import BrokenProcessPool

__all__ = ["LocalExecutor"]

log = logging.getLogger(__name__)


class _Handle:
    __slots__ = ("fn", "args", "future", "attempts", "finished")

    def __init__(self, fn, args) -> None:
        self.fn, self.args, self.future, self.attempts, self.finished = fn, args, None, 0, False


def _init_local(parent_pid: int) -> None:
    from lipgen._lifeline import die_with_parent
    from lipgen.campaign.stages import limit_threads

    die_with_parent(parent_pid)
    limit_threads()


class LocalExecutor:
    """Tasks on ``workers`` local processes (spawned, one core and one BLAS thread each).

    Parameters
    ----------
    workers : int
        Processes, in [1, 256].
    retries : int
        Times a task whose worker died is run again before its handle reports the
        ``BrokenProcessPool`` error.
    """

    kind = "local"

    def __init__(self, workers: int = 2, retries: int = 2) -> None:
        if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= 256:
            raise ValueError(f"workers must be a whole number in [1, 256], got {workers!r}")
        self._n, self.retries, self.dashboard_url = workers, retries, None
        self._slots: list[ProcessPoolExecutor | None] = [None] * workers  # made when first needed
        self._running: dict[int, _Handle] = {}  # slot -> the task it runs
        self._queue: collections.deque[_Handle] = collections.deque()
        self.lost = 0  # tasks run again because their worker died

    @property
    def workers(self) -> int:
        return self._n

    def _pool(self, slot: int) -> ProcessPoolExecutor:
        if self._slots[slot] is None:
            self._slots[slot] = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"),
                                                    initializer=_init_local, initargs=(os.getpid(),))
        return self._slots[slot]

    def _dispatch(self) -> None:
        for slot in range(self._n):
            if not self._queue:
                return
            if slot not in self._running:
                h = self._queue.popleft()
                h.attempts += 1
                h.future = self._pool(slot).submit(h.fn, *h.args)
                self._running[slot] = h

    def put(self, obj):
        """``obj`` itself: it is pickled with each task."""
        return obj

    def submit(self, fn, *args) -> _Handle:
        """Run ``fn(*args)`` on a local process (when one is free); returns its handle."""
        h = _Handle(fn, args)
        self._queue.append(h)
        self._dispatch()
        return h

    def _reap(self) -> None:
        """Free the slots whose task ended; a task whose worker died goes back to the queue."""
        for slot, h in list(self._running.items()):
            if not h.future.done():
                continue
            del self._running[slot]
            if isinstance(h.future.exception(), BrokenProcessPool):  # this worker died, with this task
                self._slots[slot].shutdown(wait=False, cancel_futures=True)
                self._slots[slot] = None
                if h.attempts <= self.retries:
                    log.warning("a local worker died running %s; that task is run again", h.fn.__name__)
                    self.lost += 1
                    self._queue.appendleft(h)
                    continue
            h.finished = True
        self._dispatch()

    def wait(self, handles, timeout: float = 0.5) -> list:
        """The ``handles`` that finished within ``timeout`` seconds (a task lost with a dead worker
        is submitted again and is not finished)."""
        handles = list(handles)
        if not handles:
            return []
        running = [h.future for h in self._running.values()]
        if running and not any(h.finished for h in handles):
            futures_wait(running, timeout=timeout, return_when=FIRST_COMPLETED)
        self._reap()
        return [h for h in handles if h.finished]

    def result(self, handle: _Handle):
        """The task's value (waiting for it), or its exception raised here."""
        while not handle.finished:
            self.wait([handle])
            if not handle.finished and not self._running:
                time.sleep(0.01)
        return handle.future.result()

    def shutdown(self) -> None:
        """Stop the processes (queued tasks are dropped)."""
        self._queue.clear()
        for pool in self._slots:
            if pool is not None:
                pool.shutdown(wait=True, cancel_futures=True)
        self._slots = [None] * self._n
        self._running.clear()
