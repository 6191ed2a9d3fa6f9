"""The thread policy: one BLAS/OpenMP thread where the work is many tiny calls.

numpy's OpenBLAS wakes all its threads for every call, however small. On a machine whose
cores are busy with other processes (CI, a shared workstation, a pool of workers), a stack of
7x7 solves then waits on threads that are not scheduled: measured on 2 cores under load, one
batched solve took 0.244 ms on 2 threads and 0.014 ms on 1, and ``reconstruct`` of 60 frames
took 70-100 s instead of 8 s. So (see CONTRIBUTING.md, "Threads"):

* per-frame and per-marker work (dot fitting, tracking, normalisation, reach over frames, NRSfM
  on tracks) runs inside :func:`blas_threads` ``(1)``;
* every worker process calls :func:`limit_worker_threads` first (its siblings use the other
  cores); that also makes Mesa's software rasterizer (llvmpipe, which starts one thread per core
  in every GL context) rasterize in the rendering thread (``LP_NUM_THREADS=0``), so a worker
  given one core uses one: its two threads did 30 % of a render worker's work, and two workers
  ran 6 threads on 2 cores. CPU per frame is the same either way (interleaved A/B, 2 workers,
  load 22-29: 0.98x); on a loaded machine the extra threads win a larger share of the cores
  (wall 0.86x), which is taken from the other processes, not efficiency;
* large factorisations and SVDs (the physics of a fine mesh) keep the default threads.
"""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Callable
from contextlib import contextmanager

__all__ = ["blas_threads", "single_threaded", "limit_worker_threads", "THREAD_ENV", "RENDER_THREAD_ENV",
           "POLICY_ENV"]

THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")
"""Environment variables that fix the thread count of a process's BLAS/OpenMP at load time."""

RENDER_THREAD_ENV = {"LP_NUM_THREADS": "0"}
"""Environment of a render worker's GL: Mesa llvmpipe rasterizes in the calling thread (read when
the first GL context is made; the images are the same bytes with any thread count)."""

POLICY_ENV = "LIPGEN_THREAD_POLICY"
"""Set to ``off`` to make :func:`blas_threads` a no-op (to measure what the policy buys)."""

_CONTROLLERS: dict[tuple, object] = {}


def _controller():
    """A threadpoolctl controller over the loaded BLAS/OpenMP libraries.

    Building one scans the loaded libraries (~3 ms), so it is cached, keyed by the modules that
    bring their own (scipy's and cvxopt's OpenBLAS, OpenCV); a new one is built when they load.
    """
    from threadpoolctl import ThreadpoolController

    key = tuple(m in sys.modules for m in ("scipy.linalg", "cvxopt", "cv2", "sklearn", "torch"))
    if key not in _CONTROLLERS:
        _CONTROLLERS[key] = ThreadpoolController()
    return _CONTROLLERS[key]


@contextmanager
def blas_threads(n: int | None = 1, *, always: bool = False):
    """Limit BLAS and OpenMP to ``n`` threads inside the ``with`` block (``None``: no change).

    Cheap enough (~0.1 ms) to wrap a per-frame call; nests (the inner limit wins until it ends).

    Parameters
    ----------
    n : int or None
        Thread count (>= 1), or ``None`` for no change.
    always : bool
        Limit even when ``LIPGEN_THREAD_POLICY=off``: for work whose *result*, not only its speed,
        depends on the thread count (NRSfM: a BLAS reduction split across threads adds in another
        order, and its nonlinear steps amplify the last-bit differences).
    """
    if n is not None and (isinstance(n, bool) or int(n) != n or n < 1):
        raise ValueError(f"thread count must be a whole number >= 1 or None, got {n!r}")
    if n is None or (os.environ.get(POLICY_ENV) == "off" and not always):
        yield
        return
    with _controller().limit(limits=int(n)):
        yield


def single_threaded(fn: Callable | None = None, *, always: bool = False) -> Callable:
    """Decorator: run ``fn`` with one BLAS/OpenMP thread (for functions of many tiny calls).

    Use it bare (``@single_threaded``) or with ``always=True`` (``@single_threaded(always=True)``:
    one thread even when ``LIPGEN_THREAD_POLICY=off``, see :func:`blas_threads`).
    """
    if fn is None:
        return functools.partial(single_threaded, always=always)

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with blas_threads(1, always=always):
            return fn(*args, **kwargs)

    return wrapper


def limit_worker_threads(n: int = 1) -> None:
    """First call of a worker process: ``n`` BLAS/OpenMP threads for the rest of its life.

    Sets the environment (for libraries loaded later, and the worker's own children) and limits
    the libraries already loaded; a worker's GL contexts made after this call rasterize in the
    rendering thread (:data:`RENDER_THREAD_ENV`; not with ``LIPGEN_THREAD_POLICY=off``).
    """
    for var in THREAD_ENV:
        os.environ[var] = str(n)
    if os.environ.get(POLICY_ENV) != "off":
        os.environ.update(RENDER_THREAD_ENV)
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=n)
