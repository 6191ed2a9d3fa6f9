"""BLAS thread policy of NRSfM: one thread, always.

Every step works on small matrices (2F x P tracks with P below a few hundred, 3K x 3K normal
equations, per-frame blocks), where a second BLAS thread gains nothing and on a loaded 2-core
machine costs a great deal (drink at K = 12: 4.3 s on one thread, 8.1 s on two, and up to 100x
slower when other work competes for the cores). One thread also makes the results independent
of the caller's thread settings: a BLAS reduction split across threads adds in another order,
and the nonlinear steps amplify such last-bit differences.
"""

from __future__ import annotations

import functools

__all__ = ["single_blas_thread"]


def single_blas_thread(func):
    """Run ``func`` with every BLAS/OpenMP pool limited to one thread (threadpoolctl)."""
    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1):
            return func(*args, **kwargs)

    return wrapper
