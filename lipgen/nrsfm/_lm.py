"""A small dense Levenberg-Marquardt, deterministic by construction.

scipy's MINPACK ``method="lm"`` gave different corrective triples for the same input once other
work had run in the process (measured on drink: the first call and later calls differ in the
last bits, and the difference grows through the rest of the pipeline). This solver has no
state: the same input gives the same bytes, given the same BLAS thread count (see
:func:`lipgen._threads.blas_threads`, ``always=True``).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack, solve_triangular

__all__ = ["levenberg_marquardt"]

_SETTLING = 1e-3
"""A step that lowers the cost by less than this fraction of it: the start is settling (``beat``)."""


def levenberg_marquardt(fun, jac, x0: np.ndarray, max_iter: int = 200, ftol: float = 1e-15,
                        xtol: float = 1e-15, beat: float | None = None,
                        match: tuple[float, float] | None = None) -> tuple[np.ndarray, float, int]:
    """Minimise ``0.5 |fun(x)|^2`` from ``x0`` by Levenberg-Marquardt with Marquardt's scaling.

    Each step solves ``min |J dx + r|^2 + lam |D^(1/2) dx|^2`` with ``D`` the running maximum of
    ``diag(J^T J)`` (as MINPACK scales), through a QR factorisation of J as MINPACK does (the
    normal equations square J's condition number and stall near exact solutions); each trial of
    ``lam`` then eliminates the damping's diagonal from J's R, as MINPACK's ``qrsolv`` does
    (:class:`_DampedStep`); ``lam`` shrinks after a step that lowers the cost and grows otherwise.

    Parameters
    ----------
    fun : callable, x (n,) -> (m,) float
    jac : callable, x (n,) -> (m, n) float
    x0 : (n,) float
    max_iter : int
        Cap on Jacobian evaluations.
    ftol, xtol : float
        Stop when an accepted step lowers the cost by less than ``ftol`` of it, or moves x by less
        than ``xtol`` of its norm.
    beat : float, optional
        A cost to beat (another start's): give up once a step lowers the cost by less than
        0.1 % and the cost, falling at that rate for every step left, would still stay above
        ``beat`` (a start settling into a worse minimum; on drink at K = 12 such a start took 116
        of the search's 144 steps).
    match : (float, float), optional
        Stop once the cost lies within these bounds (another start's minimum, reached again: the
        search needs only to know that it was).

    Returns
    -------
    x : (n,) float
    cost : float
        ``0.5 |fun(x)|^2``.
    n_iter : int
    """
    x = np.array(x0, dtype=np.float64)
    r = fun(x)
    cost = 0.5 * float(r @ r)
    lam = 1e-3
    D = np.zeros(x.size)
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 (returned)
        if cost == 0.0:
            break
        J = jac(x)
        D = np.maximum(D, (J * J).sum(0))
        # R of [J | r] holds J's R and Q^T r in its last column (Q is never formed)
        Rjr = _r_factor(J, r)
        Rj, qtr = Rjr[:x.size, :x.size], Rjr[:x.size, x.size]
        # a parameter with no effect so far (a zero column) keeps MINPACK's scale 1 and does not
        # move: the SVD's round-off in its coordinate, over a scale of ~0, had grown to ~1e146
        dead = D == 0
        step_of = _DampedStep(Rj, qtr, np.where(dead, 1.0, np.sqrt(D)))
        accepted = False
        while lam < 1e16:
            dx = step_of(lam)
            dx[dead] = 0.0
            xn = x + dx
            rn = fun(xn)
            new = 0.5 * float(rn @ rn)
            if np.isfinite(new) and new < cost:
                accepted = True
                break
            lam = max(10 * lam, 1e-15)
        if not accepted:
            break
        gain = (cost - new) / cost
        step = float(np.linalg.norm(dx))
        x, r, cost = xn, rn, new
        lam = lam / 10 if lam > 1e-15 else 0.0  # Gauss-Newton near the solution: no damping floor
        if gain < ftol or step <= xtol * float(np.linalg.norm(x)):
            break
        if match is not None and match[0] <= cost <= match[1]:
            break
        if (beat is not None and cost > beat and gain < _SETTLING
                and (beat <= 0.0 or np.log(cost / beat) > -(max_iter - it) * np.log1p(-gain))):
            break
    return x, cost, it


_GEQRT_COLUMNS = 64
"""From this many columns of ``[J | r]`` on, the QR runs LAPACK's ``dgeqrt`` (blocks of
:data:`_GEQRT_BLOCK` columns); below, ``dgeqrf``."""
_GEQRT_BLOCK = 32
_TPQRT_BLOCK = 16
"""Block size of :class:`_DampedStep`'s ``dtpqrt`` (8-32 timed alike on n = 18-117)."""


def _r_factor(J: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The upper triangle R of the QR factorisation of ``[J | r]`` (m, n + 1), its first n + 1 rows.

    Householder QR on one Fortran-ordered copy, only the rows that hold R made triangular
    (``scipy.linalg.qr`` copies the stacked array to Fortran order and clears the whole m x (n + 1)).
    Below :data:`_GEQRT_COLUMNS` columns LAPACK's ``dgeqrf`` with the workspace it asks for, as
    ``scipy.linalg.qr(mode="r")`` calls it (the same bits). From there on ``dgeqrt``: the same
    Householder reflections (the same R to rounding, the same signs), but its panels are factored
    recursively with matrix products, where ``dgeqrf``'s are column by column (BLAS-2): on drink's
    2204 x 118 blocks, 2.7 ms against 5.7-6.3 ms on one thread.
    """
    m, n = J.shape
    a = np.empty((m, n + 1), order="F")
    a[:, :n] = J
    a[:, n] = r
    if n + 1 >= _GEQRT_COLUMNS and m >= _GEQRT_BLOCK:
        qr, _, info = lapack.dgeqrt(_GEQRT_BLOCK, a, overwrite_a=True)
        routine = "dgeqrt"
    else:
        lwork = int(lapack.dgeqrf(a, lwork=-1, overwrite_a=True)[-2][0].real)
        qr, _, _, info = lapack.dgeqrf(a, lwork=lwork, overwrite_a=True)
        routine = "dgeqrf"
    if info != 0:
        raise ValueError(f"LAPACK {routine} failed (info {info}) on [J | r] of shape {a.shape}")
    return np.triu(qr[:n + 1])


class _DampedStep:
    """The step ``dx`` minimising ``|Rj dx + qtr|^2 + lam |root * dx|^2`` for any number of ``lam``.

    Each ``lam > 0`` is the least-squares solution of the stacked ``[Rj; sqrt(lam) diag(root)]``, as
    MINPACK's ``qrsolv`` finds it: Rj is already triangular, so the QR of the stack is LAPACK's
    ``dtpqrt`` of a triangle over a diagonal, about n^3 / 3 multiply-adds (drink, n = 117: 0.19 ms,
    against 1.9 ms for an SVD of Rj, which served every ``lam`` of a Jacobian, and more for a general
    least-squares solve of the stack); then one triangular solve. ``lam`` 0 (Gauss-Newton near the
    solution, where the gauge directions leave Rj singular) is the minimum-norm least-squares step of
    ``[Rj; 0]``.
    """

    def __init__(self, Rj: np.ndarray, qtr: np.ndarray, root: np.ndarray):
        if not (np.isfinite(Rj).all() and np.isfinite(qtr).all()):
            raise FloatingPointError("Levenberg-Marquardt: the Jacobian or the residual holds NaN or inf")
        self.Rj, self.qtr, self.root = Rj, qtr, root

    def __call__(self, lam: float) -> np.ndarray:
        n = self.root.size
        if lam == 0.0:
            rhs = np.concatenate([-self.qtr, np.zeros(n)])
            return np.linalg.lstsq(np.vstack([self.Rj, np.zeros((n, n))]), rhs, rcond=None)[0]
        rows = self.Rj.shape[0]                        # < n when J had fewer rows than columns
        top = np.zeros((n + 1, n + 1), order="F")      # [[Rj, qtr], [0, 0]]: upper triangular
        top[:rows, :n] = self.Rj
        top[:rows, n] = self.qtr
        bottom = np.zeros((n, n + 1), order="F")       # [sqrt(lam) diag(root), 0]
        bottom[np.arange(n), np.arange(n)] = np.sqrt(lam) * self.root
        R, _, _, info = lapack.dtpqrt(n, min(_TPQRT_BLOCK, n), top, bottom, overwrite_a=True,
                                      overwrite_b=True)
        if info != 0:
            raise ValueError(f"LAPACK dtpqrt failed (info {info}) on the damped {n} x {n} system")
        return -solve_triangular(R[:n, :n], R[:n, n], check_finite=False)

