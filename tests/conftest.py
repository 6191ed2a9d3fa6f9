"""Fixtures shared by more than one test module."""

import numpy as np
import pytest

from lipgen import Physics, dofs, lip_mesh
from lipgen.modes.model import ModeModel


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
    if request.module.__name__.rpartition(".")[2] in _OWN_THREADS:
        yield
        return
    from lipgen._threads import blas_threads

    with blas_threads(1, always=True):
        yield
