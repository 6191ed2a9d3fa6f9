"""The precomputed pieces of a reach (thesis eq 4.3, Appendix A) for one set of goal DOFs.

:meth:`lipgen.fem.physics.Physics.reach` caches one plan per goal-DOF set, so that many frames with
the same goals cost one matrix product each.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from lipgen._threads import blas_threads
from lipgen.errors import SingularStiffnessError

__all__ = ["ForcePlan", "EnergyPlan", "force_plan", "energy_plan"]


@dataclass(frozen=True)
class ForcePlan:
    """Precomputed pieces of eq 4.3 for one set of goal DOFs.

    With S = K_s⁻¹ restricted to the goal columns (3n x d) = Q R, eq 4.3's
    F = S (SᵀS)⁻¹ U_g = Q R⁻ᵀ U_g, and U = K_s⁻¹ F = Z R⁻ᵀ U_g with Z = K_s⁻¹ Q.
    """

    Q: np.ndarray  # (3n, d)
    R: np.ndarray  # (d, d) upper triangular
    Z: np.ndarray  # (3n, d)


@dataclass(frozen=True)
class EnergyPlan:
    """The least-strain-energy reach for one set of goal DOFs: S = K_s⁻¹ P (3n x d) and the
    Cholesky factor L of C = S[d] = P K_s⁻¹ P; U = S C⁻¹ U_g."""

    S: np.ndarray  # (3n, d)
    L: np.ndarray  # (d, d) lower triangular


def force_plan(factor, S: np.ndarray, free_dofs: np.ndarray, n_dofs: int) -> ForcePlan:
    """The least-norm-force plan (eq 4.3) from the goal columns of the compliance.

    Parameters
    ----------
    factor : lipgen.fem.solver.Factor
        The factorised grounded stiffness K_s.
    S : (f, d) float
        The free rows of K_s⁻¹ restricted to the d goal columns.
    free_dofs : (f,) int
        The free DOFs, indices into the 3n vector.
    n_dofs : int
        3n.

    Returns
    -------
    ForcePlan
        Q and Z are (3n, d) with zeros on anchored DOFs.

    Raises
    ------
    SingularStiffnessError
        When the goal DOFs are numerically redundant.
    """
    W = factor.solve(S)  # K_s⁻¹ S: both block solves before the QR, Z = W R⁻¹
    with blas_threads(1):  # tall-skinny BLAS-3: 2 threads cost 5-40x the wall time under load
        qr = cholesky_qr2(S)
        Qf, R = qr if qr is not None else np.linalg.qr(S)
        Zf = sla.blas.dtrsm(1.0, R, W, side=1, overwrite_b=1)  # W R⁻¹ = K_s⁻¹ Q
    diag = np.abs(np.diag(R))
    if diag.min() <= 1e-12 * diag.max():
        raise SingularStiffnessError(
            f"the goal DOFs are (numerically) redundant: their compliance columns are dependent "
            f"(smallest/largest |R_ii| = {diag.min() / diag.max():.1e}); drop duplicate or "
            f"coincident goal nodes")
    Q = np.zeros((n_dofs, S.shape[1]))
    Z = np.zeros((n_dofs, S.shape[1]))
    Q[free_dofs] = Qf
    Z[free_dofs] = Zf
    return ForcePlan(Q, R, Z)


def energy_plan(S: np.ndarray, d: np.ndarray) -> EnergyPlan:
    """The least-strain-energy plan: S and the Cholesky factor of its goal rows.

    Parameters
    ----------
    S : (3n, d) float
        K_s⁻¹ P, the compliance's goal columns.
    d : (d,) int
        The goal DOFs.

    Returns
    -------
    EnergyPlan

    Raises
    ------
    SingularStiffnessError
        When the goal DOFs are numerically redundant.
    """
    try:
        L = np.linalg.cholesky(S[d])  # C = K_s⁻¹[d, d], symmetric positive definite
    except np.linalg.LinAlgError as exc:
        raise SingularStiffnessError("the goal DOFs are (numerically) redundant: their compliance "
                                     "block is singular; drop duplicate goal nodes") from exc
    return EnergyPlan(S, L)


def cholesky_qr2(S: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Thin QR of a tall (m, d) matrix by Cholesky QR applied twice (level-3 BLAS only).

    S = Q₁R₁ from the Cholesky factor of SᵀS, then Q₁ = Q R₂ again; R = R₂R₁. Orthogonal to
    round-off when cond(S) is below ~1e8 (Yamamoto et al. 2015); on one thread, 0.06-0.07 s of CPU
    for 135,000 x 48 against 0.30-0.56 s for numpy's Householder QR (measured at load 15-25).
    Returns None (the caller takes Householder) when SᵀS is not numerically positive definite or
    cond(S) may exceed ~1e6.

    Parameters
    ----------
    S : (m, d) float, m >= d

    Returns
    -------
    (Q, R) : (m, d) float and (d, d) upper-triangular float, or None
    """
    try:
        R1 = sla.cholesky(S.T @ S)
    except np.linalg.LinAlgError:
        return None
    diag = np.abs(np.diag(R1))
    if not np.isfinite(diag).all() or diag.min() <= 1e-6 * diag.max():
        return None
    Q1 = sla.blas.dtrsm(1.0, R1, S, side=1)  # S R₁⁻¹
    try:
        R2 = sla.cholesky(Q1.T @ Q1)
    except np.linalg.LinAlgError:
        return None
    return sla.blas.dtrsm(1.0, R2, Q1, side=1, overwrite_b=1), R2 @ R1
