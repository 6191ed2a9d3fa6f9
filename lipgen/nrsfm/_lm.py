"""A small dense Levenberg-Marquardt, deterministic by construction.

scipy's MINPACK ``method="lm"`` gave different corrective triples for the same input once other
work had run in the process (measured on drink: the first call and later calls differ in the
last bits, and the difference grows through the rest of the pipeline). This solver has no
state: the same input gives the same bytes, given the same BLAS thread count (see
:func:`lipgen._threads.blas_threads`, ``always=True``).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack

__all__ = ["levenberg_marquardt"]

_SETTLING = 1e-3
"""A step that lowers the cost by less than this fraction of it: the start is settling (``beat``)."""


def levenberg_marquardt(fun, jac, x0: np.ndarray, max_iter: int = 200, ftol: float = 1e-15,
                        xtol: float = 1e-15, beat: float | None = None,
                        match: tuple[float, float] | None = None) -> tuple[np.ndarray, float, int]:
    """Minimise ``0.5 |fun(x)|^2`` from ``x0`` by Levenberg-Marquardt with Marquardt's scaling.

    Each step solves ``min |J dx + r|^2 + lam |D^(1/2) dx|^2`` with ``D`` the running maximum of
    ``diag(J^T J)`` (as MINPACK scales), through a QR factorisation of J as MINPACK does (the
    normal equations square J's condition number and stall near exact solutions), and one SVD of
    the scaled n x n factor per Jacobian that serves every trial of ``lam`` (:class:`_DampedStep`);
    ``lam`` shrinks after a step that lowers the cost and grows otherwise.

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


def _r_factor(J: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The upper triangle R of the QR factorisation of ``[J | r]`` (m, n + 1), its first n + 1 rows.

    LAPACK's ``dgeqrf`` with the workspace it asks for, as ``scipy.linalg.qr(mode="r")`` calls it (the
    same bits), but on one Fortran-ordered copy, and only the rows that hold R made triangular
    (``scipy.linalg.qr`` copies the stacked array to Fortran order and clears the whole m x (n + 1)).
    """
    m, n = J.shape
    a = np.empty((m, n + 1), order="F")
    a[:, :n] = J
    a[:, n] = r
    lwork = int(lapack.dgeqrf(a, lwork=-1, overwrite_a=True)[-2][0].real)
    qr, _, _, info = lapack.dgeqrf(a, lwork=lwork, overwrite_a=True)
    if info != 0:
        raise ValueError(f"LAPACK dgeqrf failed (info {info}) on [J | r] of shape {a.shape}")
    return np.triu(qr[:n + 1])


class _DampedStep:
    """The step ``dx`` minimising ``|Rj dx + qtr|^2 + lam |root * dx|^2`` for any number of ``lam``.

    With ``y = root * dx`` this is ridge regression on ``B = Rj / root``: one SVD ``B = U s V^T`` per
    Jacobian, then each ``lam > 0`` costs two products, ``y = -V (s / (s^2 + lam)) U^T qtr`` (as MINPACK
    reuses its QR across the damping's trials, where a least-squares solve of the stacked
    ``[Rj; sqrt(lam) diag(root)]`` per trial took most of the search's time on short sequences). ``lam``
    0 (Gauss-Newton near the solution, where the gauge directions leave Rj singular) is the minimum-norm
    least-squares step of ``[Rj; 0]``, as before.
    """

    def __init__(self, Rj: np.ndarray, qtr: np.ndarray, root: np.ndarray):
        self.Rj, self.qtr, self.root = Rj, qtr, root
        self._svd = None

    def __call__(self, lam: float) -> np.ndarray:
        n = self.root.size
        if lam == 0.0:
            rhs = np.concatenate([-self.qtr, np.zeros(n)])
            return np.linalg.lstsq(np.vstack([self.Rj, np.zeros((n, n))]), rhs, rcond=None)[0]
        if self._svd is None:
            U, s, Vt = np.linalg.svd(self.Rj / self.root, full_matrices=False)
            self._svd = (s, U.T @ self.qtr, Vt)
        s, c, Vt = self._svd
        return -(Vt.T @ (s * c / (s * s + lam))) / self.root
