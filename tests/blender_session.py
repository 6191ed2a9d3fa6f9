"""One Blender (pip ``bpy``) process shared by the tests of a test process.

bpy is a large module with global state (one scene, one undo stack, its own USD libraries), so
the add-on tests never import it into the pytest process. A :class:`BlenderSession` starts one
worker process (spawned, so nothing is inherited but ``sys.path`` and the environment), imports
bpy there once, and runs check functions in it: ``session.run("module:check_x", args...)``. The
check functions live in plain modules beside this file (``bpy_checks_*.py``) so the worker can
import them by name; an assertion that fails in the worker is re-raised here with the worker's
traceback attached.

Every check starts from an empty factory scene (``read_factory_settings``), so the test modules
share one session (:func:`shared_session`) as each module's tests already shared theirs: one bpy
start per test process (about 0.55 s of CPU) instead of one per module and per USD probe. The
price: each test process keeps its Blender worker (about 300 MB) until it exits.
"""

from __future__ import annotations

import atexit
import importlib.util
import multiprocessing as mp
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def bpy_available() -> bool:
    return importlib.util.find_spec("bpy") is not None


def _init_worker(env: dict[str, str]) -> None:
    os.environ.update(env)
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    # a spawned child inherits the parent's sys.path: where the parent imported bpy in-process (the
    # Cycles renderer does), that holds bpy's scripts/modules folder, whose bpy/ shadows the package
    sys.path[:] = [p for p in sys.path if not Path(p, "bpy", "ops.py").is_file()]
    import bpy  # noqa: F401  (import once, up front, so the first check is not slowed by it)


def _call(target: str, args, kwargs):
    """Worker side of :meth:`BlenderSession.run`: import ``module`` and call ``function``."""
    import importlib

    module, _, name = target.partition(":")
    return getattr(importlib.import_module(module), name)(*args, **kwargs)


class BlenderSession:
    """A worker process with bpy imported; see the module docstring."""

    def __init__(self, env: dict[str, str] | None = None) -> None:
        ctx = mp.get_context("spawn")
        self._pool = ProcessPoolExecutor(max_workers=1, mp_context=ctx, initializer=_init_worker,
                                         initargs=(dict(env or {}),))
        self.broken = False

    def run(self, target: str, *args, timeout: float | None = None, **kwargs):
        """Call ``"module:function"`` with ``args`` in the Blender process; return its result.

        The module is imported only in the worker (it imports bpy), never here. No timeout by
        default: how long a check takes depends on the machine's load, not on lipgen (a worker that
        dies raises ``BrokenProcessPool`` at once).
        """
        try:
            return self._pool.submit(_call, target, args, kwargs).result(timeout=timeout)
        except BrokenProcessPool:
            self.broken = True
            raise

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)


_SHARED: list[BlenderSession] = []


def shared_session() -> BlenderSession:
    """This test process's Blender session, started at first use and closed at exit; a new one
    replaces a session whose worker died (that test fails, the next ones get a live Blender)."""
    if not _SHARED or _SHARED[-1].broken:
        session = BlenderSession()
        atexit.register(session.close)
        _SHARED.append(session)
    return _SHARED[-1]
