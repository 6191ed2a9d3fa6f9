"""Head pose as the rotation that leaves the least physical deformation (a normalisation).

The nose mark is the only head-fixed mark: it pins the head's translation, leaving the rotation
about it. Per frame, :func:`least_cost_rotations` finds the rotation R (3 parameters,
Gauss-Newton on the rotation vector) minimising the physical cost of the residual marker
displacement

    y(R) = (s R (X - nose) + model_nose) - model_markers,      cost = yᵀ W y,

where W comes from the lip model itself (:class:`MarkerMetric`):

- ``"force"``: the squared norm of the least force that reaches y, FᵀF of ``Physics.reach``
  (eq 4.3): ``W = (SᵀS)⁻¹`` with S the compliance columns K_s⁻¹ of the marker DOFs;
- ``"energy"``: the least strain energy reaching y (times 2): ``W = C_oo⁻¹``, C_oo = K_s⁻¹ at
  the marker DOFs.

Only the visible markers' DOFs enter (the sub-block of SᵀS or C_oo), which is the exact cost of
the least field that reaches just those goals. The scale s is the similarity's, fitted on the
reference frame as in the thesis.

Why it works, and where it does not. A rigid rotation of the lips about the nose drags them
against the anchored border and strip, so it costs force; so do real expressions, and part of an
expression can be explained more cheaply by a small head rotation. That bias is measured in
:mod:`lipgen.normalize`'s docstring (per action: e.g. a full one-sided corner puller reads as
about 3.6 deg of head rotation under the force metric, a full jaw opening as 2.6 deg of nod).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ._validate import as_float_array

__all__ = ["METRICS", "MarkerMetric", "rotation_vector", "rotation_matrix", "least_cost_rotations"]

log = logging.getLogger(__name__)

METRICS = ("force", "energy")
"""Kinds of :class:`MarkerMetric`: least force norm (eq 4.3) or least strain energy."""


@dataclass(frozen=True, eq=False)
class MarkerMetric:
    """A quadratic cost ``yᵀ W y`` of marker displacements y (P markers, 3 DOFs each, mm).

    Attributes
    ----------
    gram : (3P, 3P) float
        Symmetric positive definite; for visible DOFs v the cost matrix is ``inv(gram[v][:, v])``.
    kind : str
        ``"force"`` (gram = SᵀS), ``"energy"`` (gram = C_oo) or ``"euclidean"`` (identity).
    """

    gram: np.ndarray
    kind: str

    @property
    def n_markers(self) -> int:
        return len(self.gram) // 3

    @classmethod
    def from_physics(cls, physics, kind: str = "force") -> MarkerMetric:
        """The metric of ``physics`` (a :class:`lipgen.fem.Physics`) at its mesh's marker nodes."""
        from .fem import dofs

        if kind not in METRICS:
            raise ValueError(f"unknown marker metric {kind!r}; choose one of {METRICS}")
        d = dofs(np.asarray(physics.mesh.markers))
        S = physics.compliance_columns(d)  # (3n, 3P): displacement per unit force at each marker DOF
        gram = S.T @ S if kind == "force" else S[d]
        gram = 0.5 * (gram + gram.T)
        return cls(gram / np.trace(gram) * len(gram), kind)  # scaled: only the shape matters

    @classmethod
    def euclidean(cls, n_markers: int) -> MarkerMetric:
        """Plain sum of squared marker displacements (a Procrustes fit about the nose)."""
        return cls(np.eye(3 * int(n_markers)), "euclidean")

    def root(self, visible) -> np.ndarray:
        """(3v, 3v) L with ``L Lᵀ = W`` for the visible markers ``visible (P,) bool``."""
        v = np.repeat(np.asarray(visible, bool), 3)
        G = self.gram[np.ix_(v, v)]
        # W = G⁻¹ = L Lᵀ with L = chol(G)⁻ᵀ; the residual Lᵀ y = solve(chol(G), y).
        return np.linalg.inv(np.linalg.cholesky(G)).T


def rotation_matrix(w) -> np.ndarray:
    """Rodrigues: (..., 3) rotation vectors (rad) -> (..., 3, 3) rotations."""
    w = np.asarray(w, dtype=np.float64)
    th = np.linalg.norm(w, axis=-1)[..., None, None]
    K = _skew(w)
    small = th < 1e-8
    safe = np.where(small, 1.0, th)
    a = np.where(small, 1.0 - th**2 / 6, np.sin(safe) / safe)
    b = np.where(small, 0.5 - th**2 / 24, (1 - np.cos(safe)) / safe**2)
    return np.eye(3) + a * K + b * K @ K


def rotation_vector(R) -> np.ndarray:
    """(..., 3, 3) rotations -> (..., 3) rotation vectors (rad), angles below pi."""
    R = np.asarray(R, dtype=np.float64)
    v = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    c = np.clip((np.trace(R, axis1=-2, axis2=-1) - 1) / 2, -1.0, 1.0)
    th = np.arccos(c)[..., None]
    s = np.sin(th)
    return np.where(th < 1e-8, 0.5 * v, v * th / (2 * np.where(s == 0, 1.0, s)))


def _skew(a: np.ndarray) -> np.ndarray:
    Z = np.zeros((*a.shape[:-1], 3, 3))
    Z[..., 0, 1], Z[..., 0, 2], Z[..., 1, 2] = -a[..., 2], a[..., 1], -a[..., 0]
    return Z - np.swapaxes(Z, -1, -2)


def least_cost_rotations(points, targets, metric: MarkerMetric, visible, start, iterations: int = 30,
                         tol: float = 1e-10) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per frame, the rotation R minimising ``yᵀ W y`` with ``y = R a - b`` on the visible markers.

    Parameters
    ----------
    points : (F, P, 3) float
        ``a``: nose-relative marks, already scaled (NaN allowed where not visible).
    targets : (P, 3) float
        ``b``: the model's rest markers relative to the model's nose.
    metric : MarkerMetric
        The cost (``metric.n_markers == P``).
    visible : (F, P) bool
        Markers that enter each frame's cost; frames with fewer than 3 get NaN.
    start : (3, 3) float
        Initial rotation of every frame.
    iterations, tol : int, float
        Gauss-Newton limits: at most ``iterations`` steps, stop when the step is below ``tol`` rad.

    Returns
    -------
    R : (F, 3, 3) float
        NaN for frames that could not be solved (too few markers, or all on a line through the
        nose, where a rotation about that line is free).
    cost : (F,) float
        ``yᵀ W y`` at the solution (mm², in the metric's scaling).
    converged : (F,) bool
    """
    A = as_float_array(points, "points", (None, None, 3), finite=False)
    F, P, _ = A.shape
    B = as_float_array(targets, "targets", (P, 3))
    vis = np.asarray(visible, bool)
    if vis.shape != (F, P):
        raise ValueError(f"visible must have shape ({F}, {P}), got {vis.shape}")
    if metric.n_markers != P:
        raise ValueError(f"the metric is for {metric.n_markers} markers but the data have {P}; build it "
                         "from the model whose marker nodes these are")
    R0 = as_float_array(start, "start", (3, 3))
    out = np.full((F, 3, 3), np.nan)
    cost = np.full(F, np.nan)
    conv = np.zeros(F, bool)
    roots: dict[bytes, np.ndarray] = {}
    for f in range(F):
        v = vis[f]
        if v.sum() < 3:
            continue
        L = roots.setdefault(v.tobytes(), metric.root(v))
        a, b = A[f, v], B[v]
        R = R0.copy()
        degenerate = False
        for _ in range(iterations):
            ra = a @ R.T
            r = L.T @ (ra - b).ravel()
            J = L.T @ (-_skew(ra)).reshape(-1, 3)  # d(w x ra)/dw = -[ra]x
            sv = np.linalg.svd(J, compute_uv=False)
            if sv[-1] <= 1e-9 * sv[0]:
                degenerate = True
                break
            step = np.linalg.lstsq(J, -r, rcond=None)[0]
            R = rotation_matrix(step) @ R
            if np.linalg.norm(step) < tol:
                conv[f] = True
                break
        if degenerate:
            continue
        if not conv[f]:
            log.warning("frame %d: the head rotation did not settle in %d Gauss-Newton steps", f, iterations)
        out[f] = R
        y = (a @ R.T - b).ravel()
        cost[f] = float(np.sum((L.T @ y) ** 2))
    return out, cost, conv
