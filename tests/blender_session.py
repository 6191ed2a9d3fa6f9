"""One Blender (pip ``bpy``) process shared by the tests of a module.

bpy is a large module with global state (one scene, one undo stack, its own USD libraries), so
the add-on tests never import it into the pytest process. A :class:`BlenderSession` starts one
worker process (spawned, so nothing is inherited but ``sys.path`` and the environment), imports
bpy there once, and runs check functions in it: ``session.run("module:check_x", args...)``. The
check functions live in plain modules beside this file (``bpy_checks_*.py``) so the worker can
import them by name; an assertion that fails in the worker is re-raised here with the worker's
traceback attached.
"""

from __future__ import annotations

import importlib.util
import multiprocessing as mp
import os
import sys
from concurrent.futures import ProcessPoolExecutor
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

    def run(self, target: str, *args, timeout: float | None = None, **kwargs):
        """Call ``"module:function"`` with ``args`` in the Blender process; return its result.

        The module is imported only in the worker (it imports bpy), never here. No timeout by
        default: how long a check takes depends on the machine's load, not on lipgen (a worker that
        dies raises ``BrokenProcessPool`` at once).
        """
        return self._pool.submit(_call, target, args, kwargs).result(timeout=timeout)

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)
