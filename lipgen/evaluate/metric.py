"""The one definition of the Table 5.1 error, shared by ``lipgen evaluate`` and ``lipgen experiment table51``.

**Error per hidden DOF** (mm²): the squared difference between the estimate and the reference,
averaged over the test frames and over each frame's *hidden* DOFs: the free DOFs of the model
(not anchored) that the frame's observation does not contain. Observed DOFs are left out (an
LLSE without noise returns them exactly, which would dilute the error by the share observed),
and so are anchored DOFs (0 in every estimate and, up to the truth's own anchor motion, in
every reference).

**Relative error**: the error per hidden DOF over the mean square of the reference itself on
the same DOFs and frames, i.e. over the error of predicting no motion. A value of 1 is no
better than predicting rest; the absolute figure alone says little when the test motion is small.
"""

from __future__ import annotations

import numpy as np

__all__ = ["hidden_dofs", "per_dof_error", "relative_error", "ERROR_DEFINITION"]

ERROR_DEFINITION = ("mean squared error per hidden DOF (mm²): over the test frames and the free DOFs "
                    "each frame does not observe; relative: over the mean square of the reference on "
                    "the same DOFs (1 = predicting no motion)")
"""One line for reports."""


def hidden_dofs(free_dofs, observed) -> np.ndarray:
    """(h,) int: the free DOFs (``Physics.free_dofs``, (f,) int) not in ``observed`` (d,) int."""
    return np.setdiff1d(np.asarray(free_dofs, int), np.asarray(observed, int))


def _squared(estimates, reference, hidden):
    E = np.asarray(estimates, float)
    R = np.asarray(reference, float)
    F = len(R)
    if E.shape[0] != F or E.reshape(F, -1).shape != R.reshape(F, -1).shape:
        raise ValueError(f"estimates {E.shape} and reference {R.shape} must hold the same frames and DOFs")
    h = np.asarray(hidden, int)
    if h.size == 0:
        raise ValueError("no hidden DOFs: every free DOF is observed, there is nothing to estimate")
    return (E.reshape(F, -1)[:, h] - R.reshape(F, -1)[:, h]) ** 2, R.reshape(F, -1)[:, h] ** 2


def per_dof_error(estimates, reference, hidden) -> float:
    """Mean squared error per hidden DOF, mm².

    Parameters
    ----------
    estimates, reference : (F, n, 3) or (F, 3n) float
        Estimated and reference displacement fields of the test frames, mm.
    hidden : (h,) int
        The hidden DOFs (:func:`hidden_dofs`), the same in every frame.
    """
    return float(np.mean(_squared(estimates, reference, hidden)[0]))


def relative_error(estimates, reference, hidden) -> float:
    """:func:`per_dof_error` over the mean square of ``reference`` on the same DOFs (dimensionless;
    1 = predicting no motion). Shapes as :func:`per_dof_error`."""
    err, ms = _squared(estimates, reference, hidden)
    total = float(np.mean(ms))
    return float(np.mean(err)) / total if total > 0 else float("nan")
