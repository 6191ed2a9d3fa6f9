"""Sparse factorisation of the grounded stiffness K_s (symmetric positive definite).

Three backends, chosen by ``method``:

* ``"cholmod"``: supernodal sparse Cholesky (SuiteSparse CHOLMOD with its AMD ordering) through
  ``cvxopt.cholmod``. cvxopt installs from PyPI wheels (``pip install 'lipgen[fast]'``); it is
  GPL-3 licensed, which is why it stays optional. About 3x faster to factor than SuperLU at
  50,000 nodes and about 2x faster to solve (``lipgen bench --suite physics``).
  Many right-hand sides go through CHOLMOD in one call (level-3 BLAS per supernode,
  :mod:`lipgen.fem._cholmod_dense`), not column by column as cvxopt's own ``solve`` does.
* ``"cholespy"``: CHOLMOD as bundled by cholespy (BSD-3, PyPI wheels: ``pip install
  'lipgen[fast-bsd]'``), for installations without GPL code. It solves a block of right-hand
  sides in one call, but its factorisation is ~4x slower than cvxopt's here (it factorises
  without the supernodal BLAS path) and it reports no pivots.
* ``"superlu"``: scipy's SuperLU (``splu``) in symmetric mode, minimum-degree ordering on
  AᵀA + A, no pivoting (K_s is SPD). Pure scipy, always available.

Options measured on a 51,200-node bent sheet (153,600 DOFs; factor / one solve, load ~2 on 2
cores): cvxopt's supernodal CHOLMOD 0.64 s / 36 ms (chosen); SuperLU with MMD on AᵀA+A 2.3 s /
75 ms (COLAMD: more fill; a geometric nested dissection given as the ordering: 2.0 s / 65 ms
with more fill); cholespy (CHOLMOD, PyPI wheels) 4.5 s / 38 ms; pypardiso (MKL) 0.63 s /
170 ms but ~1 GB of MKL wheels; qdldl 5.0 s / 96 ms; python-mumps (LU only) 1.4 s / 90 ms;
scikit-sparse has no wheel here.

Measured at 33,000 free DOFs (resolution 3; factor / 48 right-hand sides): cvxopt CHOLMOD
0.19 s / 0.12 s in one call (0.51 s column by column); cholespy 0.75 s / 0.37 s; SuperLU
1.05 s / 1.64 s (``lipgen bench --suite physics``, ``multi_rhs``).

``"auto"`` takes cvxopt's CHOLMOD when cvxopt imports, else cholespy, else SuperLU. Either way
the factor is checked before use: a non-positive or tiny pivot, or a known solution that does not
come back, raises :class:`~lipgen.errors.SingularStiffnessError` instead of returning garbage.
Nothing here forms a dense inverse.
"""

from __future__ import annotations

import logging
from contextlib import contextmanager

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from lipgen.errors import SingularStiffnessError
from lipgen.tol import tol

__all__ = ["SOLVERS", "Factor", "factorize", "cholmod_available", "cholmod_supernodal", "cholespy_available"]

log = logging.getLogger(__name__)

SOLVERS: tuple[str, ...] = ("auto", "cholmod", "cholespy", "superlu")
"""Sparse factorisations: ``auto`` (cvxopt's CHOLMOD, else cholespy, else SuperLU), or one by name."""

_PIVOT_RATIO = 1e-13
"""Smallest/largest pivot (of the LDLᵀ form) below which K_s counts as numerically singular;
the default lips at resolutions 0-4 sit at 2e-2 to 5e-2 (either grounding)."""
_FORWARD_ERROR = 1e-4
"""Relative error on a known solution above which the factor is rejected (condition ~1e12)."""

_HINT = ("Check that the anchors hold every piece of the mesh (at least two anchors, not all on "
         "one line) and that no face has a zero or absurdly small E")


def cholmod_available() -> bool:
    """True when ``cvxopt.cholmod`` imports (the fast path)."""
    try:
        import cvxopt.cholmod  # noqa: F401
    except ImportError:
        return False
    return True


@contextmanager
def cholmod_supernodal():
    """CHOLMOD's options set for a supernodal LLᵀ (BLAS-3; ``cholmod.diag`` needs it) inside the
    ``with`` block and restored after it: cvxopt keeps them in one dict for the whole process."""
    from cvxopt import cholmod

    saved = dict(cholmod.options)
    cholmod.options["supernodal"] = 2
    try:
        yield
    finally:
        cholmod.options.clear()
        cholmod.options.update(saved)


def cholespy_available() -> bool:
    """True when ``cholespy`` imports (CHOLMOD under a BSD licence)."""
    try:
        import cholespy  # noqa: F401
    except ImportError:
        return False
    return True


class Factor:
    """A factorised SPD matrix: ``solve(B)`` returns ``A⁻¹ B`` for ``B`` of shape (N,) or (N, k).

    Attributes
    ----------
    method : str
        ``"cholmod"``, ``"cholespy"`` or ``"superlu"``.
    size : int
        N.
    pivot_ratio : float
        Smallest over largest pivot of the factorisation (an inverse-condition indicator); NaN
        for cholespy, which does not expose its pivots (the known-solution check still applies).
    multi_column : bool
        True when a block of right-hand sides is solved in one call (checked by :meth:`check`);
        False when the columns go one at a time.
    """

    def __init__(self, A: sp.csc_matrix, method: str) -> None:
        self.size = A.shape[0]
        self.method = method
        self.multi_column = method != "cholmod"
        if method == "cholmod":
            self._factor_cholmod(A)
        elif method == "cholespy":
            self._factor_cholespy(A)
        else:
            self._factor_superlu(A)

    # ---- backends --------------------------------------------------------------------------
    def _factor_cholmod(self, A: sp.csc_matrix) -> None:
        import cvxopt
        from cvxopt import cholmod

        low = sp.tril(A, format="coo")
        M = cvxopt.spmatrix(cvxopt.matrix(low.data.astype(np.float64)),
                            cvxopt.matrix(low.row.astype(np.int64)),
                            cvxopt.matrix(low.col.astype(np.int64)), A.shape)
        try:
            with cholmod_supernodal():
                F = cholmod.symbolic(M, uplo="L")
                cholmod.numeric(M, F)
        except ArithmeticError as exc:
            raise SingularStiffnessError(
                f"the grounded stiffness ({self.size} DOFs) is not positive definite: CHOLMOD "
                f"met a non-positive pivot ({exc}). {_HINT}") from exc
        self._F = F
        d = np.array(cholmod.diag(F)).ravel() ** 2
        self.pivot_ratio = float(d.min() / d.max())

    def _factor_cholespy(self, A: sp.csc_matrix) -> None:
        from cholespy import CholeskySolverD, MatrixType

        A = sp.csc_matrix(A)
        A.sort_indices()
        try:
            self._chol = CholeskySolverD(self.size, A.indptr.astype(np.int32), A.indices.astype(np.int32),
                                         np.ascontiguousarray(A.data, np.float64), MatrixType.CSC)
        except ValueError as exc:  # "Matrix is not positive definite!"
            raise SingularStiffnessError(
                f"the grounded stiffness ({self.size} DOFs) is not positive definite: cholespy says "
                f"{exc}. {_HINT}") from exc
        self.pivot_ratio = float("nan")

    def _factor_superlu(self, A: sp.csc_matrix) -> None:
        try:
            lu = spla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                           options={"SymmetricMode": True})
        except RuntimeError as exc:  # "Factor is exactly singular"
            raise SingularStiffnessError(
                f"the grounded stiffness ({self.size} DOFs) is singular: SuperLU says {exc}. "
                f"{_HINT}") from exc
        d = lu.U.diagonal()
        if (d <= 0).any() or not np.isfinite(d).all():
            raise SingularStiffnessError(
                f"the grounded stiffness ({self.size} DOFs) is not positive definite: SuperLU met "
                f"{int((d <= 0).sum())} non-positive pivot(s). {_HINT}")
        self._lu = lu
        self.pivot_ratio = float(d.min() / d.max())

    # ---- use -------------------------------------------------------------------------------
    def solve(self, B: np.ndarray) -> np.ndarray:
        """``A⁻¹ B`` for ``B`` of shape (N,) or (N, k)."""
        B = np.asarray(B, np.float64)
        if B.shape[0] != self.size or B.ndim not in (1, 2):
            raise ValueError(f"right-hand side must have shape ({self.size},) or ({self.size}, k), "
                             f"got {B.shape}")
        if self.method == "superlu":
            return self._lu.solve(np.asfortranarray(B) if B.ndim == 2 else B)
        if self.method == "cholespy":
            rhs = np.ascontiguousarray(B)
            out = np.zeros_like(rhs)
            self._chol.solve(rhs, out)
            return out
        if B.ndim == 2 and B.shape[1] > 1 and self.multi_column:
            X = self._solve_block(B)
            if X is not None:
                return X
        return self._solve_columns(B)

    def _solve_block(self, B: np.ndarray) -> np.ndarray | None:
        from lipgen.fem._cholmod_dense import dense_solve

        return dense_solve(self._F, B)

    def _solve_columns(self, B: np.ndarray) -> np.ndarray:
        """cvxopt's solve, one column at a time (its multi-column solve loops the same way)."""
        import cvxopt
        from cvxopt import cholmod

        cols = B.reshape(self.size, -1)
        out = np.empty(cols.shape)
        for j in range(cols.shape[1]):
            x = cvxopt.matrix(np.ascontiguousarray(cols[:, j]))
            cholmod.solve(self._F, x)
            out[:, j] = np.frombuffer(x, dtype=np.float64)
        return out.reshape(B.shape)

    def factor_nnz(self, A: sp.spmatrix) -> int:
        """Stored nonzeros of the factor of ``A`` (L for CHOLMOD; L + U for SuperLU): the work of
        a solve. For CHOLMOD it factorises ``A`` again, since extracting L (``getfactor``)
        spoils the factor it is taken from; meant for benchmarks, not for the hot path."""
        if self.method == "superlu":
            return int(self._lu.L.nnz + self._lu.U.nnz)
        if self.method == "cholespy":
            raise ValueError("cholespy does not expose its factor; factor_nnz needs 'cholmod' or 'superlu'")
        from cvxopt import cholmod

        spare = Factor(sp.csc_matrix(A), "cholmod")
        return len(cholmod.getfactor(spare._F).V)

    def check(self, A: sp.spmatrix) -> None:
        """Raise :class:`SingularStiffnessError` if the factor of ``A`` is not trustworthy."""
        if self.method == "cholmod":
            self._check_block(A)
        if self.pivot_ratio < _PIVOT_RATIO:
            raise SingularStiffnessError(
                f"the grounded stiffness ({self.size} DOFs) is numerically singular: its smallest "
                f"pivot is {self.pivot_ratio:.2e} of the largest. {_HINT}")
        x = np.random.default_rng(0).standard_normal(self.size)
        b = A @ x
        y = self.solve(b)
        residual = np.linalg.norm(A @ y - b) / np.linalg.norm(b)
        error = np.linalg.norm(y - x) / np.linalg.norm(x)
        if not residual <= tol.solve or not error <= _FORWARD_ERROR:
            raise SingularStiffnessError(
                f"the factorised grounded stiffness ({self.size} DOFs) does not reproduce a known "
                f"solution (relative residual {residual:.1e}, error {error:.1e}); it is too close "
                f"to singular. {_HINT}")


    def _check_block(self, A: sp.spmatrix) -> None:
        """Turn on the one-call multi-column solve if it reproduces the column loop."""
        X = np.random.default_rng(1).standard_normal((self.size, 2))
        B = np.asarray(A @ X)
        block = self._solve_block(B)
        if block is None:
            return
        loop = self._solve_columns(B)
        scale = np.abs(loop).max()
        if block.shape == loop.shape and np.abs(block - loop).max() <= 1e-10 * scale:
            self.multi_column = True
        else:
            log.warning("CHOLMOD's multi-column solve disagrees with the column loop; solving "
                        "column by column")


def factorize(A: sp.spmatrix, method: str = "auto") -> Factor:
    """Factorise the SPD sparse matrix ``A`` once and check the factor.

    Parameters
    ----------
    A : (N, N) sparse
        Symmetric positive definite (the grounded stiffness K_s).
    method : {"auto", "cholmod", "cholespy", "superlu"}

    Returns
    -------
    Factor
        Checked; ``solve(B)`` takes (N,) or (N, k).
    """
    if method not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {method!r}")
    if method == "auto":
        method = ("cholmod" if cholmod_available() else "cholespy" if cholespy_available()
                  else "superlu")
    elif method == "cholmod" and not cholmod_available():
        from lipgen._optional import require

        require("cvxopt.cholmod", "solver='cholmod'")
    elif method == "cholespy" and not cholespy_available():
        from lipgen._optional import require

        require("cholespy", "solver='cholespy'")
    A = sp.csc_matrix(A)
    factor = Factor(A, method)
    factor.check(A)
    log.debug("factorised %d DOFs with %s (pivot ratio %.1e)", A.shape[0], method, factor.pivot_ratio)
    return factor
