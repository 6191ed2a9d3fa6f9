"""Low-rank completion of tracks with unobserved entries: Gauss-Newton on the complement subspace.

The model is ``W ~ M B + t 1^T`` (rank ``r`` plus a translation per row, W of shape (2F, P)): every
row of W lies in a subspace V of R^P of dimension ``r + 1`` that holds the all-ones vector. Let N
(P x d, d = P - 1 - r) be an orthonormal basis of V's complement. For a row w with hidden points
H (a frame's u and v rows share them), the least-squares fit in V to its observed entries leaves
the residual norm

    |e|^2 = a^T Pi a,   a = N^T w~,   Pi = I - N_H^T (N_H N_H^T)^-1 N_H,

with w~ the row with zeros at H and N_H the rows of N at H (Pi projects onto the null space of N_H;
a frame with h >= d hidden points fits exactly). The cost is a function of span(N) alone, with
``r d`` degrees of freedom, and each row's residual is a d-vector, so a Gauss-Newton step costs
O(F (r^2 + d^2)) plus one ``r d``-square solve - the same as one sweep of alternating least squares,
which creeps when r + 1 is close to P (drink, K = 12: 36 of 40 dimensions; 500 sweeps did not
converge). The Jacobian's two terms are orthogonal (``Pi N_H^+ = 0``), so ``J^T J`` is a sum of
two Kronecker products per row.

The hidden entries x of a row then solve ``N_H^T x = -a`` in the least-squares sense. With h > d
hidden points that system is under-determined (the model leaves h - d of them free); of its
solutions the one nearest a prior is taken: the point's own track interpolated linearly in time
between the frames where it is seen (truth-free; the free directions were otherwise left to where
alternating least squares happened to stop; :mod:`lipgen.nrsfm.time_prior` holds the prior and the fill).
"""

from __future__ import annotations

import functools
import logging

import numpy as np
import scipy.linalg

from lipgen._memory import reuse_freed_memory
from lipgen.nrsfm.time_prior import fill_hidden, interpolate_in_time, prior_variance

__all__ = ["complete_subspace", "SubspaceCompletion", "interpolate_in_time", "prior_variance"]

log = logging.getLogger(__name__)


class _Frames:
    """The frames with h hidden points, 0 <= h < d (the others fit exactly), grouped by h."""

    def __init__(self, W0: np.ndarray, mask: np.ndarray, d: int):
        F, P = mask.shape
        hidden = (~mask).sum(1)
        self.groups = []
        for h in range(min(d, P)):
            frames = np.flatnonzero(hidden == h)
            if frames.size == 0:
                continue
            idx = np.nonzero(~mask[frames])[1].reshape(frames.size, h)
            rows = W0.reshape(F, 2, P)[frames]                     # (n, 2, P), zeros at hidden points
            self.groups.append((idx, rows))
        self._last = None   # (N, cost, terms) of the last fit: an accepted trial step's, reused

    def _fit(self, N: np.ndarray) -> tuple[float, list]:
        """Half the squared residual at N (P x d) and, per group, the terms the normal matrix reuses:
        ``NH`` (n, h, d), ``Ginv`` (n, h, h), ``c`` (n, 2, h) and ``res = Pi a`` (n, 2, d) (None for
        the first three where h = 0). Those of the last N are kept and returned again while N holds
        the same values."""
        if self._last is not None and np.array_equal(self._last[0], N):
            return self._last[1], self._last[2]
        cost = 0.0
        terms = []
        for idx, rows in self.groups:
            h = idx.shape[1]
            a = rows @ N                                          # (n, 2, d)
            if h:
                NH = N[idx]                                       # (n, h, d)
                Ginv = _inverse_or_pseudo(NH @ NH.transpose(0, 2, 1))
                c = np.einsum("nij,njd,nkd->nki", Ginv, NH, a)    # (n, 2, h)
                res = a - np.einsum("nki,nid->nkd", c, NH)        # Pi a
            else:
                NH = Ginv = c = None
                res = a
            cost += 0.5 * float((res * a).sum())
            terms.append((NH, Ginv, c, res))
        self._last = (N.copy(), cost, terms)
        return cost, terms

    def evaluate(self, N: np.ndarray, Y: np.ndarray | None = None):
        """Half the squared residual; with Y (the subspace's own basis, P x r) also the Gauss-Newton
        normal matrix (r d x r d) and gradient (r d), unknowns ordered (l, j) for ``dN = Y dX``.
        The residual terms of the last N are kept: the normal matrix at an accepted trial step does
        not compute them again (the same values)."""
        d = N.shape[1]
        cost, terms = self._fit(N)
        if Y is None:
            return cost
        r = Y.shape[1]
        # Every product below is symmetric in its r pair and in its d pair, so only the upper triangles
        # are formed (a quarter of the work) and the normal matrix is gathered from them.
        ur, ud = np.triu_indices(r), np.triu_indices(d)
        H = np.zeros((ur[0].size, ud[0].size))
        g = np.zeros((r, d))
        eye = np.eye(d)[ud][None]
        for (idx, rows), (NH, Ginv, c, res) in zip(self.groups, terms, strict=True):
            beta = rows @ Y                                       # (n, 2, r)
            if idx.shape[1]:
                YH = Y[idx]                                       # (n, h, r)
                beta = beta - c @ YH
                DtD = (YH.transpose(0, 2, 1) @ Ginv @ YH)[:, ur[0], ur[1]]        # (n, r(r+1)/2)
                rr = np.einsum("nkj,nki->nji", res, res)[:, ud[0], ud[1]]         # (n, d(d+1)/2)
                Pi = eye - (NH.transpose(0, 2, 1) @ Ginv @ NH)[:, ud[0], ud[1]]   # for the normal matrix only
                bb = np.einsum("nkl,nkm->nlm", beta, beta)[:, ur[0], ur[1]]
                H += np.concatenate([bb, DtD]).T @ np.concatenate([Pi, rr])
            else:
                bb = np.einsum("nkl,nkm->lm", beta, beta)[ur]
                H += bb[:, None] * eye[0]
            g += np.einsum("nkl,nkj->lj", beta, res)
        JtJ = H.ravel()[_gather_index(r, d)]
        return cost, JtJ, g.ravel()


@functools.lru_cache(maxsize=2)
def _gather_index(r: int, d: int) -> np.ndarray:
    """(r d, r d) int: where entry ((l, j), (m, k)) of the normal matrix sits in the (r(r+1)/2, d(d+1)/2)
    table of upper-triangle pairs ((min(l, m), max(l, m)), (min(j, k), max(j, k)))."""
    def pair(n):
        i, j = np.minimum.outer(np.arange(n), np.arange(n)), np.maximum.outer(np.arange(n), np.arange(n))
        return i * n - i * (i - 1) // 2 + (j - i)      # row-major position of (i, j) in the upper triangle
    pr, pd = pair(r), pair(d)
    ds = d * (d + 1) // 2
    out = pr[:, None, :, None] * ds + pd[None, :, None, :]   # (l, j, m, k)
    out = out.reshape(r * d, r * d)
    out.flags.writeable = False
    return out


def _damped_step(JtJ: np.ndarray, diag: np.ndarray, lam: float, g: np.ndarray) -> np.ndarray:
    """The Levenberg-Marquardt step ``-(JtJ + lam diag(diag))^-1 g`` by Cholesky (the matrix is symmetric
    positive definite: half the work of a general LU). LinAlgError where it is not, in floating point."""
    A = JtJ.copy()
    A[np.diag_indices_from(A)] += lam * diag        # the same sums as adding np.diag(lam * diag), in place
    factor = scipy.linalg.cho_factor(A, lower=True, overwrite_a=True, check_finite=False)
    return scipy.linalg.cho_solve(factor, -g, check_finite=False)


def _inverse_or_pseudo(G: np.ndarray) -> np.ndarray:
    """(n, h, h) inverses of the Gram matrices ``G = N_H N_H^T`` (n, h, h). Where one is singular or
    too ill-conditioned for its inverse to be trusted (``G G^-1`` more than ``1e-3`` from the
    identity: the hidden points' rows of N are dependent or nearly so, and the model leaves those
    entries partly free, as in a long gap of several points), that frame takes the Moore-Penrose
    pseudo-inverse (``rcond`` 1e-12), which gives the projector onto the row space of N_H. Every
    other frame keeps its plain inverse, bit for bit (numpy inverts each matrix of a stack alone)."""
    n, h, _ = G.shape
    try:
        out = np.linalg.inv(G)
    except np.linalg.LinAlgError:     # some matrix exactly singular: find them, invert the rest
        w = np.linalg.eigvalsh(G)
        bad = ~(w[:, 0] > 1e-12 * w[:, -1])
        out = np.zeros_like(G)
        if not bad.all():
            out[~bad] = np.linalg.inv(G[~bad])
    else:
        bad = np.zeros(n, dtype=bool)
    bad |= ~(np.abs(G @ out - np.eye(h)).max(axis=(1, 2)) <= 1e-3)   # also NaN from a singular one
    if bad.any():
        out[bad] = np.linalg.pinv(G[bad], rcond=1e-12, hermitian=True)
    return out


def _start_rows(start, P: int, rank: int) -> np.ndarray:
    """``start`` as a finite (m, P) float array with m > ``rank`` (enough rows to span a rank-``rank``
    model besides the translation), or a ValueError naming its shape."""
    rows = np.asarray(start, dtype=np.float64)
    if rows.ndim != 2 or rows.shape[1] != P or rows.shape[0] <= rank:
        raise ValueError(f"start must be complete rows over the tracks' {P} points, more than the rank "
                         f"{rank} of them, shape (m > {rank}, {P}); got shape {rows.shape}")
    if not np.isfinite(rows).all():
        raise ValueError(f"start (shape {rows.shape}) has {int((~np.isfinite(rows)).sum())} NaN or infinite "
                         "entries; it must be complete tracks")
    return rows


def _bases(N: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal N (P x d, orthogonal to the ones vector) and its complement Y within 1^perp."""
    P, d = N.shape
    Q = np.linalg.qr(np.column_stack([np.ones(P) / np.sqrt(P), N]), mode="complete")[0]
    return Q[:, 1: d + 1], Q[:, d + 1:]


def complete_subspace(W: np.ndarray, mask: np.ndarray, rank: int, max_iter: int = 100,
                      tol: float = 1e-9, resume: SubspaceCompletion | None = None, start=None
                      ) -> tuple[np.ndarray, float, dict]:
    """Complete tracks with the best rank-``rank`` plus translation model (Levenberg-Marquardt).

    Parameters
    ----------
    W : (2F, P) float
        Tracks; entries at hidden points are ignored.
    mask : (F, P) bool
        Observed points; not all True.
    rank : int
        r, with ``r <= P - 1``.
    max_iter : int
        Cap on Levenberg-Marquardt steps.
    tol : float
        Stop when a step lowers the cost by less than this fraction, or the cost falls below
        ``(1e-14 |W|)^2``.
    resume : SubspaceCompletion, optional
        The same completion (same W, mask, rank, tol) stopped at a lower cap: its steps are not run
        again (the result is bit for bit that of one run with ``max_iter``).
    start : (m, P) array_like, optional
        Complete rows over the same P points (e.g. the completed tracks of a longer sequence that holds
        these frames) whose best rank-``rank`` row space the fit starts from, instead of that of the
        tracks interpolated in time. A start near the answer saves steps (about half, measured on noisy
        tracks and on halves of a sequence); the answer is this fit's own (the observed entries alone
        decide where it converges). Not with ``resume``.

    Returns
    -------
    full : (2F, P) float
        W with the hidden entries read off the model (observed entries unchanged).
    misfit : float
        RMS of the model's residual on the observed entries over their RMS about each row's mean.
    info : dict
        ``steps``, ``cost`` (first, last: half the squared residual of W / ``scale``), ``scale`` (the
        power of two W was divided by, so that any magnitude is solved alike), ``state`` (the
        :class:`SubspaceCompletion`, to resume with a higher cap).
    """
    if isinstance(max_iter, bool) or not isinstance(max_iter, int | np.integer) or max_iter < 0:
        raise ValueError(f"max_iter must be an integer >= 0, got {max_iter!r}")
    if resume is None:
        state = SubspaceCompletion(W, mask, rank, tol, start)
    elif start is not None:
        raise ValueError("start is for a new completion; resume goes on from where its own run stopped")
    else:
        _check_resume(resume, W, mask, rank, tol, max_iter)
        state = resume
    state.run(max_iter)
    full, misfit, info = state.result()
    return full * state.unit, misfit, info | {"scale": state.unit, "state": state}


def _check_resume(state, W, mask, rank: int, tol: float, max_iter: int) -> None:
    """Refuse a ``resume`` state that is not this completion's (other tracks, mask, rank or tol), or
    that has already run past ``max_iter`` steps."""
    if not isinstance(state, SubspaceCompletion):
        raise TypeError(f"resume must be a SubspaceCompletion (info['state'] of an earlier call), "
                        f"got {type(state).__name__}")
    mask = np.asarray(mask)
    same = (mask.shape == state.mask.shape and np.array_equal(mask, state.mask)
            and state.d == mask.shape[1] - 1 - rank and state.tol == tol
            and np.array_equal(np.where(np.repeat(mask, 2, axis=0), W, 0.0) / state.unit, state.W0))
    if not same:
        raise ValueError(f"resume is the state of another completion (its mask {state.mask.shape}, "
                         f"rank {state.mask.shape[1] - 1 - state.d}, tol {state.tol!r}; here "
                         f"{mask.shape}, rank {rank}, tol {tol!r}, or other tracks): resume only the "
                         "same call with a higher max_iter")
    if state.steps > max_iter:
        raise ValueError(f"resume has already run {state.steps} steps, more than max_iter = {max_iter}")


class SubspaceCompletion:
    """:func:`complete_subspace`'s iterations, which can stop at a cap and go on later.

    Parameters
    ----------
    W : (2F, P) float
    mask : (F, P) bool
    rank : int
    tol : float
    start : (m, P) array_like, optional
        As :func:`complete_subspace`.
    """

    def __init__(self, W: np.ndarray, mask: np.ndarray, rank: int, tol: float = 1e-9, start=None):
        seen = np.repeat(mask, 2, axis=0)
        W0 = np.where(seen, W, 0.0)
        top = float(np.abs(W0).max())
        self.unit = 2.0 ** np.round(np.log2(top)) if top > 0 else 1.0   # exact rescale: squares stay in range
        W0 = W0 / self.unit
        F, P = mask.shape
        self.W0, self.mask, self.tol = W0, mask, tol
        self.prior = interpolate_in_time(W0, mask)
        self.d = d = P - 1 - rank
        row_mean = W0.sum(1) / seen.sum(1)
        self.spread = float(np.linalg.norm(np.where(seen, W0 - row_mean[:, None], 0.0)))
        self.steps, self.done, self.frames = 0, d <= 0, None
        if self.done:   # every row fits exactly: the model says nothing about the hidden entries
            return
        source = self.prior if start is None else _start_rows(start, P, rank)
        _, _, Vt = np.linalg.svd(source - source.mean(1, keepdims=True), full_matrices=False)
        self.N, self.Y = _bases(np.linalg.qr(np.column_stack([np.ones(P), Vt[:rank].T]),
                                             mode="complete")[0][:, rank + 1:])
        self.frames = _Frames(W0, mask, d)
        self.cost, self.JtJ, self.g = self.frames.evaluate(self.N, self.Y)
        self.first = self.cost
        self.floor = 0.5 * (1e-14 * float(np.linalg.norm(W0))) ** 2
        self.lam = 1e-4

    def run(self, max_iter: int) -> None:
        """Levenberg-Marquardt steps until converged or ``max_iter`` steps in all. Freed memory is
        kept for reuse meanwhile (:func:`lipgen._memory.reuse_freed_memory`): every step makes and
        frees arrays of about a megabyte, whose pages were otherwise faulted in again (the same
        values)."""
        with reuse_freed_memory():
            self._run(max_iter)
        if self.frames is not None:   # kept terms are reused only within a run (a resumed run recomputes)
            self.frames._last = None

    def _run(self, max_iter: int) -> None:
        d = self.d
        N, Y, cost, JtJ, g, lam = (None, None, 0.0, None, None, 0.0) if self.done else (
            self.N, self.Y, self.cost, self.JtJ, self.g, self.lam)
        if JtJ is None and not self.done:   # kept small while stopped: the same values again, bit for bit
            cost, JtJ, g = self.frames.evaluate(N, Y)
        steps = self.steps
        for steps in range(self.steps + 1, max_iter + 1):  # noqa: B007 (the count is kept after the loop)
            if self.done:
                break
            if cost <= self.floor:
                self.done = True
                break
            diag = np.maximum(np.diag(JtJ), 1e-12 * max(float(np.diag(JtJ).max()), 1e-300))
            accepted = False
            while not accepted and lam < 1e12:
                try:
                    step = _damped_step(JtJ, diag, lam, g)
                except np.linalg.LinAlgError:   # not positive definite in floating point: damp more
                    lam *= 10
                    continue
                Nn, Yn = _bases(np.linalg.qr(N + Y @ step.reshape(Y.shape[1], d))[0])
                new = self.frames.evaluate(Nn)
                if new < cost:
                    accepted = True
                    gain = (cost - new) / cost
                    N, Y, cost = Nn, Yn, new
                    if gain < self.tol or steps == max_iter or cost <= self.floor:
                        JtJ = g = None   # the last step: its normal matrix would not be used
                    else:
                        JtJ, g = self.frames.evaluate(N, Y)[1:]
                    lam = max(lam / 10, 1e-12)
                else:
                    lam *= 10
            if not accepted or gain < self.tol:
                self.done = True
                break
        if not self.done:   # stopped at the cap: the normal matrix (r d x r d) is not kept
            self.steps = max(steps, self.steps)
            self.N, self.Y, self.cost, self.JtJ, self.g, self.lam = N, Y, cost, None, None, lam
        elif self.d > 0 and N is not None:
            self.steps = steps
            self.N, self.Y, self.cost = N, Y, cost

    def result(self) -> tuple[np.ndarray, float, dict]:
        """The completed tracks (2F, P) in units of ``unit``, the misfit and ``steps``, ``cost``."""
        if self.d <= 0:
            return self.prior, 0.0, {"steps": 0, "cost": [0.0, 0.0]}
        mask, d = self.mask, self.d
        hidden = (~mask).sum(1)
        dof = 2 * int(np.maximum(d - hidden, 0).sum()) - self.Y.shape[1] * d
        noise = max(2 * self.cost / max(dof, 1), 1e-24 * float((self.W0**2).mean()), 1e-300)
        full = fill_hidden(self.W0, self.prior, mask, self.N, noise)
        misfit = float(np.sqrt(2 * max(self.cost, 0.0))) / max(self.spread, 1e-300)
        log.debug("completion (subspace Gauss-Newton): %d hidden entries, %d steps, cost %.3e -> %.3e",
                  int(2 * (~mask).sum()), self.steps, self.first, self.cost)
        return full, misfit, {"steps": self.steps, "cost": [self.first, self.cost]}
