"""The thread policy (lipgen._threads): limits where the work is many tiny BLAS calls."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from threadpoolctl import threadpool_info

from lipgen import _threads
from lipgen._threads import blas_threads, single_threaded


def _blas_threads() -> list[int]:
    return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]


def test_limit_inside_and_restored_after(monkeypatch):
    monkeypatch.delenv(_threads.POLICY_ENV, raising=False)
    before = _blas_threads()
    assert before  # numpy's OpenBLAS at least
    with blas_threads(1):
        assert _blas_threads() == [1] * len(before)
        with blas_threads(None):  # no change: the outer limit holds
            assert _blas_threads() == [1] * len(before)
    assert _blas_threads() == before


def test_policy_off_changes_nothing(monkeypatch):
    monkeypatch.setenv(_threads.POLICY_ENV, "off")
    before = _blas_threads()
    with blas_threads(1):
        assert _blas_threads() == before


def test_always_limits_even_with_the_policy_off(monkeypatch):
    """always=True (work whose result depends on the thread count) ignores LIPGEN_THREAD_POLICY=off."""
    monkeypatch.setenv(_threads.POLICY_ENV, "off")
    before = _blas_threads()
    with blas_threads(1, always=True):
        assert _blas_threads() == [1] * len(before)
    assert _blas_threads() == before

    @single_threaded(always=True)
    def seen():
        return _blas_threads()

    assert set(seen()) == {1}


def test_nrsfm_runs_on_one_thread_with_the_policy_off(monkeypatch):
    """reconstruct's determinism needs one thread: the policy switch does not lift it."""
    import lipgen.nrsfm.engine as engine
    from lipgen.nrsfm import reconstruct

    monkeypatch.setenv(_threads.POLICY_ENV, "off")
    inside = []
    real = engine.check_tracks

    def spy(*args, **kwargs):
        inside.append(_blas_threads())
        return real(*args, **kwargs)

    monkeypatch.setattr(engine, "check_tracks", spy)
    from lipgen.nrsfm.synthetic import articulated_sequence

    W, _, _ = articulated_sequence(20, np.random.default_rng(1), n_bones=4, markers_per_bone=3)
    reconstruct(W, 2)
    assert inside and set(inside[0]) == {1}


@pytest.mark.parametrize("n", [0, -1, 1.5, True, "2"])
def test_bad_thread_counts(n):
    with pytest.raises((ValueError, TypeError), match="thread count|invalid literal"):
        with blas_threads(n):
            pass


def test_decorator_limits_and_keeps_the_function(monkeypatch):
    monkeypatch.delenv(_threads.POLICY_ENV, raising=False)

    @single_threaded
    def seen(a):
        """doc"""
        return a, _blas_threads()

    a, inside = seen(3)
    assert a == 3 and set(inside) == {1} and seen.__doc__ == "doc"


def test_dot_fitting_runs_on_one_thread(monkeypatch):
    """refine_centroids (a stack of 10x10 solves per iteration) runs under the limit."""
    from lipgen.recon import dots

    monkeypatch.delenv(_threads.POLICY_ENV, raising=False)
    seen = []
    real = dots._lm_fit

    def spy(*args):
        seen.append(_blas_threads())
        return real(*args)

    monkeypatch.setattr(dots, "_lm_fit", spy)
    yy, xx = np.mgrid[0:40, 0:40]
    img = 200.0 - 150.0 * np.exp(-((xx - 20.3) ** 2 + (yy - 19.6) ** 2) / (2 * 1.5 ** 2))
    uv = dots.refine_centroids(img, np.array([[20.0, 20.0]]), sigma=1.5)
    assert np.allclose(uv, [[20.3, 19.6]], atol=0.05)
    assert seen and all(set(s) == {1} for s in seen)


def test_worker_limit_in_a_fresh_process():
    code = ("import json, numpy, threadpoolctl\nfrom lipgen._threads import limit_worker_threads\n"
            "limit_worker_threads(1)\nimport os\n"
            "print(json.dumps([[l['num_threads'] for l in threadpoolctl.threadpool_info()],"
            " os.environ['OPENBLAS_NUM_THREADS']]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    threads, env = json.loads(out.stdout)
    assert set(threads) == {1} and env == "1"
