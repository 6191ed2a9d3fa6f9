"""Sparse factorisation of the grounded stiffness K_s (symmetric positive definite).

Two backends, chosen by ``method``:

* ``"cholmod"``: supernodal sparse Cholesky (SuiteSparse CHOLMOD with its AMD ordering) through
  ``cvxopt.cholmod``. cvxopt installs from PyPI wheels (``pip install 'lipgen[fast]'``); it is
  GPL-3 licensed, which is why it stays optional. About 3x faster to factor than SuperLU at
  50,000 nodes and about 2x faster to solve (``lipgen bench --suite physics``).
* ``"superlu"``: scipy's SuperLU (``splu``) in symmetric mode, minimum-degree ordering on
  AᵀA + A, no pivoting (K_s is SPD). Pure scipy, always available.

Options measured on a 51,200-node bent sheet (153,600 DOFs; factor / one solve, load ~2 on 2
cores): cvxopt's supernodal CHOLMOD 0.64 s / 36 ms (chosen); SuperLU with MMD on AᵀA+A 2.3 s /
75 ms (COLAMD: more fill; a geometric nested dissection given as the ordering: 2.0 s / 65 ms
with more fill); cholespy (CHOLMOD, PyPI wheels) 4.5 s / 38 ms; pypardiso (MKL) 0.63 s /
170 ms but ~1 GB of MKL wheels; qdldl 5.0 s / 96 ms; python-mumps (LU only) 1.4 s / 90 ms;
scikit-sparse has no wheel here.

``"auto"`` takes CHOLMOD when cvxopt imports, else SuperLU. Either way the factor is checked
before use: a non-positive or tiny pivot, or a known solution that does not come back, raises
:class:`~lipgen.errors.SingularStiffnessError` instead of returning garbage. Nothing here forms
a dense inverse.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from lipgen.errors import SingularStiffnessError
from lipgen.tol import tol

__all__ = ["SOLVERS", "Factor", "factorize", "cholmod_available"]

log = logging.getLogger(__name__)

SOLVERS: tuple[str, ...] = ("auto", "cholmod", "superlu")
"""Sparse factorisations: ``auto`` (CHOLMOD when cvxopt is installed, else SuperLU), or one by name."""

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


class Factor:
    """A factorised SPD matrix: ``solve(B)`` returns ``A⁻¹ B`` for ``B`` of shape (N,) or (N, k).

    Attributes
    ----------
    method : str
        ``"cholmod"`` or ``"superlu"``.
    size : int
        N.
    pivot_ratio : float
        Smallest over largest pivot of the factorisation (an inverse-condition indicator).
    """

    def __init__(self, A: sp.csc_matrix, method: str) -> None:
        self.size = A.shape[0]
        self.method = method
        if method == "cholmod":
            self._factor_cholmod(A)
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
        saved = dict(cholmod.options)
        cholmod.options["supernodal"] = 2  # supernodal LLᵀ (BLAS-3); diag() needs it
        try:
            F = cholmod.symbolic(M, uplo="L")
            cholmod.numeric(M, F)
        except ArithmeticError as exc:
            raise SingularStiffnessError(
                f"the grounded stiffness ({self.size} DOFs) is not positive definite: CHOLMOD "
                f"met a non-positive pivot ({exc}). {_HINT}") from exc
        finally:
            cholmod.options.clear()
            cholmod.options.update(saved)
        self._F = F
        d = np.array(cholmod.diag(F)).ravel() ** 2
        self.pivot_ratio = float(d.min() / d.max())

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
        import cvxopt
        from cvxopt import cholmod

        # One column at a time: cvxopt's multi-column solve is slower per column than this.
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
        from cvxopt import cholmod

        spare = Factor(sp.csc_matrix(A), "cholmod")
        return len(cholmod.getfactor(spare._F).V)

    def check(self, A: sp.spmatrix) -> None:
        """Raise :class:`SingularStiffnessError` if the factor of ``A`` is not trustworthy."""
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


def factorize(A: sp.spmatrix, method: str = "auto") -> Factor:
    """Factorise the SPD sparse matrix ``A`` once and check the factor.

    Parameters
    ----------
    A : (N, N) sparse
        Symmetric positive definite (the grounded stiffness K_s).
    method : {"auto", "cholmod", "superlu"}
    """
    if method not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {method!r}")
    if method == "auto":
        method = "cholmod" if cholmod_available() else "superlu"
    elif method == "cholmod" and not cholmod_available():
        from lipgen._optional import require

        require("cvxopt.cholmod", "solver='cholmod'")
    A = sp.csc_matrix(A)
    factor = Factor(A, method)
    factor.check(A)
    log.debug("factorised %d DOFs with %s (pivot ratio %.1e)", A.shape[0], method, factor.pivot_ratio)
    return factor
