"""Fixtures shared by more than one test module."""

import sys

import numpy as np
import pytest

# Bytecode caches are written even where PYTHONDONTWRITEBYTECODE is set (as on the shared
# development machines): without them every test process compiles lipgen and rewrites the
# asserts of all test modules from source again. The collection alone took 16.4-16.5 s of CPU
# against 7.6-9.8 s with the caches (interleaved, load 6-7), paid by each xdist worker. The
# caches go in the gitignored __pycache__ folders, are written atomically, and a changed source is
# compiled again (Python's and pytest's own mtime and size checks). Subprocesses keep the
# environment's setting, and read the caches.
sys.dont_write_bytecode = False

# Imported here, before any test, and not inside the fixtures: the one-BLAS-thread fixture below
# limits the BLAS/OpenMP libraries already loaded, and these imports load them (scipy's OpenBLAS
# among them: loaded later, inside a test, it ran on two threads, and default_subject took 5-10x
# the CPU).
from lipgen import Physics, dofs, lip_mesh  # noqa: E402
from lipgen.modes.model import ModeModel  # noqa: E402


@pytest.fixture(scope="module")
def usd_mesh():
    return lip_mesh(0)


@pytest.fixture(scope="module")
def usd_fitted(usd_mesh):
    """A ModeModel trained as the thesis did (least-strain fields reaching random marker goals,
    through the FEM), and the weights of 24 held-out frames."""
    rng = np.random.default_rng(7)
    physics = Physics(usd_mesh)
    model = ModeModel(n_modes=10).fit_from_markers(physics, rng.normal(scale=2.0, size=(80, 16, 3)))
    held_out, _ = physics.reach(dofs(usd_mesh.markers), rng.normal(scale=2.0, size=(24, 48)))
    return model, model.project(held_out)


# Modules that check the thread policy itself: they see the process's own thread counts.
_OWN_THREADS = {"test_threads"}


@pytest.fixture(autouse=True)
def _one_blas_thread_per_test_worker(request):
    """Each test runs with one BLAS/OpenMP thread in this process (the environment is left alone,
    so subprocesses and worker pools see what a user's would).

    ``make test`` runs two pytest workers on two cores: a BLAS call on two threads in each
    oversubscribes them, and under load a tiny call then waits for an unscheduled thread (the
    measurements in CONTRIBUTING.md, Threads). Results do not depend on it: what must hold with
    more threads is tested with an explicit limit (``blas_threads(2)``, ``threadpool_limits(2)``)
    inside the test, which wins over this one.
    """
    yield from _one_blas_thread(request)


@pytest.fixture(autouse=True, scope="module")
def _one_blas_thread_for_module_fixtures(request):
    """The same limit around a module's fixtures: pytest builds wider-scoped fixtures before
    function-scoped ones, so without this a ``scope="module"`` fixture ran on two BLAS threads
    (a ``LinearNDInterpolator``'s tiny LAPACK calls made ``shaped_mesh`` 20-60x slower)."""
    yield from _one_blas_thread(request)


def _one_blas_thread(request):
    """One BLAS/OpenMP thread while the fixture is active, except in the modules of :data:`_OWN_THREADS`."""
    if request.module.__name__.rpartition(".")[2] in _OWN_THREADS:
        yield
        return
    from lipgen._threads import blas_threads

    with blas_threads(1, always=True):
        yield


@pytest.fixture(autouse=True)
def _keep_freed_memory():
    """Each test runs with glibc keeping freed memory for reuse (``lipgen._memory``), as
    ``generate``'s workers do: a test worker runs hundreds of tests in one process, and after the
    first ``generate`` (which puts glibc's fixed 128 KiB thresholds back at its end) every array of
    128 KiB or more was a fresh ``mmap`` whose pages the kernel faulted in and zeroed again. Where
    the memory comes from changes no value (``tests/test_memory.py`` checks the same bytes with the
    policy on and off, and sets its own thresholds); subprocesses see a user's defaults;
    ``LIPGEN_MEMORY_POLICY=off`` turns it off. In ``tests/test_e2e.py`` and ``tests/test_dataset.py``
    it took the CPU from 45.5 to 40.8 s (system time 11.1 -> 6.4 s; side by side at load 7-9)."""
    from lipgen._memory import keep_freed_memory

    keep_freed_memory()
    yield
