"""An in-process executor for campaign tests: ``run_campaign``'s own logic (chunks, stages, the
index, failure, resume, the store's staging and upload) at the cost of its rendering alone.

It has the interface of ``lipgen.campaign.LocalExecutor`` and runs each task in this process when it
is submitted. The executors' processes themselves (a worker's thread limits, a dead worker's task
run again) are tested with real processes in tests/test_campaign.py and tests/test_campaign_ray.py.
"""

import os
from contextlib import contextmanager

__all__ = ["InlineExecutor", "inline_executor"]


class _Done:
    """A finished task's value or exception (hashable: the campaign's driver keys on handles)."""

    value, error = None, None


class InlineExecutor:
    """Tasks run in this process, each when it is submitted."""

    kind, workers, dashboard_url, lost = "inline", 1, None, 0

    def put(self, obj):
        return obj

    def submit(self, fn, *args) -> _Done:
        handle = _Done()
        try:
            handle.value = fn(*args)
        except Exception as exc:  # kept for result(), as a worker's exception is
            handle.error = exc
        return handle

    def wait(self, handles, timeout: float = 0.5) -> list:
        return list(handles)

    def result(self, handle: _Done):
        if handle.error is not None:
            raise handle.error
        return handle.value

    def shutdown(self) -> None:
        pass


@contextmanager
def inline_executor(monkeypatch):
    """An :class:`InlineExecutor`; the thread limits its tasks set in the environment are undone with
    ``monkeypatch``, and the renderer its tasks keep in this process (as a worker does) is closed."""
    from lipgen._threads import RENDER_THREAD_ENV, THREAD_ENV
    from lipgen.dataset import generate as gen

    for var in (*THREAD_ENV, *RENDER_THREAD_ENV):
        if var in os.environ:
            monkeypatch.setenv(var, os.environ[var])
        else:
            monkeypatch.delenv(var, raising=False)
    try:
        yield InlineExecutor()
    finally:
        gen._close_worker()
