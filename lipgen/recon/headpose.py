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
reference frame as in the thesis. :func:`pose_normalize` (behind
``normalize_markers(method=...)``) puts it together and leaves a mis-measured marker out of a
frame's fit when the fit without it costs far less (:func:`marker_cost_shares` screens for them).

Why it works, and where it does not. A rigid rotation of the lips about the nose drags them
against the anchored border and strip, so it costs force; so do real expressions, and part of an
expression can be explained more cheaply by a small head rotation. That bias is measured in
:mod:`lipgen.recon.normalize`'s docstring (per action: e.g. a full one-sided corner puller reads as
about 3.6 deg of head rotation under the force metric, a full jaw opening as 2.6 deg of nod).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from lipgen._rotation import rotation_matrix, rotation_vector
from lipgen._rotation import skew as _skew
from lipgen._validate import as_float_array
from lipgen.recon.similarity import Normalization, Similarity, most_neutral_frame, umeyama

__all__ = ["METRICS", "MarkerMetric", "rotation_vector", "rotation_matrix", "least_cost_rotations",
           "marker_cost_shares", "pose_normalize"]

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
        from lipgen.fem import dofs

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


def marker_cost_shares(points, targets, metric: MarkerMetric, visible, rotations) -> np.ndarray:
    """(F, P) share of each frame's cost ``yᵀ W y`` that leaving marker j out of the goals removes,
    at the given rotations (0 for markers not visible; NaN rows for frames without a rotation).

    Leaving goal block j out, the least cost of the rest is ``yᵀ W y - (W y)_jᵀ (W_jj)⁻¹ (W y)_j``
    (the cost minimised over the free y_j), so the share is the second term over the first. A
    marker far off the model's account of the others (a mis-track) carries most of the cost.
    """
    A = as_float_array(points, "points", (None, None, 3), finite=False)
    F, P, _ = A.shape
    B = as_float_array(targets, "targets", (P, 3))
    vis = np.asarray(visible, bool)
    R = np.asarray(rotations, float)
    out = np.zeros((F, P))
    cache: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
    for f in range(F):
        v = vis[f]
        if not np.all(np.isfinite(R[f])) or v.sum() < 3:
            out[f] = np.nan
            continue
        key = v.tobytes()
        if key not in cache:
            idx = np.repeat(v, 3)
            W = np.linalg.inv(metric.gram[np.ix_(idx, idx)])
            blocks = np.stack([W[3 * k:3 * k + 3, 3 * k:3 * k + 3] for k in range(int(v.sum()))])
            cache[key] = (W, np.linalg.inv(blocks))
        W, inv_blocks = cache[key]
        y = (A[f, v] @ R[f].T - B[v]).ravel()
        g = (W @ y).reshape(-1, 3)
        total = float(y @ W @ y)
        if total <= 0:
            continue
        out[f, v] = np.einsum("ki,kij,kj->k", g, inv_blocks, g) / total
    return out


def pose_normalize(rel: np.ndarray, vis: np.ndarray, M: np.ndarray, model_nose, reference_frame,
                    method: str, physics, outlier_ratio: float, max_outliers: int,
                    candidates=None, reference: Similarity | None = None) -> Normalization:
    """The pose methods of :func:`lipgen.recon.normalize.normalize_markers` (which checks the input):
    one scale from the reference frame's similarity, then per frame the rotation about the nose
    of least cost (:func:`least_cost_rotations`), leaving mis-measured markers out.

    ``rel (F, P, 3)`` are the nose-relative marks, ``vis (F, P)`` the visible ones. ``reference``
    (another normalisation's ``similarity``, of the same subject) gives the scale and the rotation
    every frame's fit starts from, instead of the reference frame's similarity; the result's
    ``reference_frame`` is then -1 and its ``similarity`` is ``reference``. Passing a
    normalisation's own similarity back gives its markers again (each frame's fit starts from the
    reference frame's final rotation instead of its similarity's, and converges to the same pose).
    """

    F, P, _ = rel.shape
    if model_nose is None:
        raise ValueError(f"method {method!r} rotates about the nose and needs model_nose, the model's nose "
                         "point (3,) in the model frame (e.g. mesh.nose)")
    n0 = as_float_array(model_nose, "model_nose", (3,))
    if method == "procrustes":
        metric = MarkerMetric.euclidean(P)
    else:
        if physics is None:
            raise ValueError(f"method {method!r} weighs the residual with the lip model's physics; pass "
                             "physics=Physics(mesh) of the model whose marker nodes model_markers are")
        if len(physics.mesh.markers) != P or not np.allclose(
                physics.mesh.vertices[physics.mesh.markers], M, atol=1e-6):
            raise ValueError(f"physics is for a mesh with {len(physics.mesh.markers)} markers that are not "
                             f"model_markers ({P}, 3); build it from the same model mesh")
        metric = MarkerMetric.from_physics(physics, "force" if method == "least-force" else "energy")
    zero = np.zeros((F, P, 3))
    if reference is not None:
        return _with_reference(rel, vis, M, n0, metric, reference, method, outlier_ratio, max_outliers)
    ref = most_neutral_frame(np.where(vis[..., None], rel, 0.0), vis, M, n0, candidates) \
        if reference_frame == "auto" else int(reference_frame)
    seen = vis[ref]
    if seen.sum() < 3:
        raise ValueError(f"reference frame {ref} has only {int(seen.sum())} visible markers; the "
                         "similarity to the model needs 3")
    sim0 = umeyama(np.vstack([rel[ref, seen], np.zeros(3)]), np.vstack([M[seen], n0]))
    s = sim0.scale
    A = np.where(vis[..., None], s * rel, zero)
    R, cost, _ = least_cost_rotations(A, M - n0, metric, vis, sim0.rotation)
    outliers = _trim_outliers(A, M - n0, metric, vis, sim0.rotation, R, cost, outlier_ratio, max_outliers)
    borrowed = ~np.isfinite(cost)
    good = np.flatnonzero(~borrowed)
    if len(good) == 0:
        raise ValueError("no frame has 3 visible markers off a line through the nose; cannot normalise")
    if borrowed.any():
        nearest = good[np.abs(good[None, :] - np.arange(F)[:, None]).argmin(1)]
        R[borrowed] = R[nearest[borrowed]]
        log.warning("%d frame(s) borrowed the head rotation of a neighbour (too few visible markers)",
                    int(borrowed.sum()))
    if borrowed[ref]:
        raise ValueError(f"reference frame {ref}: no head rotation could be found (too few markers)")
    out = s * np.einsum("fij,fpj->fpi", R, rel) + n0
    out[~vis] = np.nan
    fit_rms = float(np.sqrt(np.mean(np.sum((out[ref, seen] - M[seen]) ** 2, axis=1))))
    Rref = R[ref]
    sim = Similarity(s, Rref, n0.copy())
    rotations = np.einsum("ij,fjk->fik", Rref.T, R)  # so that out = sim.apply(rotations @ rel)
    return Normalization(out, rotations, sim, np.full(F, np.nan), borrowed, fit_rms, int(ref), method, cost,
                         outliers)


def _with_reference(rel, vis, M, n0, metric, reference: Similarity, method: str, outlier_ratio: float,
                    max_outliers: int) -> Normalization:
    """:func:`pose_normalize` with the scale and start rotation of a given reference."""
    s, R0 = float(reference.scale), np.asarray(reference.rotation, dtype=np.float64)
    A = np.where(vis[..., None], s * rel, 0.0)
    R, cost, _ = least_cost_rotations(A, M - n0, metric, vis, R0)
    outliers = _trim_outliers(A, M - n0, metric, vis, R0, R, cost, outlier_ratio, max_outliers)
    borrowed = ~np.isfinite(cost)
    good = np.flatnonzero(~borrowed)
    if len(good) == 0:
        raise ValueError("no frame has 3 visible markers off a line through the nose; cannot normalise")
    if borrowed.any():
        nearest = good[np.abs(good[None, :] - np.arange(len(rel))[:, None]).argmin(1)]
        R[borrowed] = R[nearest[borrowed]]
        log.warning("%d frame(s) borrowed the head rotation of a neighbour (too few visible markers)",
                    int(borrowed.sum()))
    out = s * np.einsum("fij,fpj->fpi", R, rel) + n0
    out[~vis] = np.nan
    rotations = np.einsum("ij,fjk->fik", R0.T, R)  # so that out = reference.apply(rotations @ rel)
    sim = Similarity(s, R0, n0.copy())
    return Normalization(out, rotations, sim, np.full(len(rel), np.nan), borrowed, float("nan"), -1, method,
                         cost, outliers)


def _trim_outliers(A, B, metric, vis, start, R, cost, ratio: float, rounds: int) -> np.ndarray:
    """Leave single mis-measured markers out of the pose fits; updates ``R`` and ``cost`` in place
    and returns the (F, P) outlier mask.

    Candidates are frames where one marker carries over half the cost at the current pose
    (:func:`lipgen.recon.headpose.marker_cost_shares`, cheap); for those, the pose is re-fitted
    without each visible marker in turn, and the best one is left out if that cuts the cost
    below ``ratio`` times the current.
    """
    use = vis.copy()
    outliers = np.zeros_like(vis)
    P = vis.shape[1]
    for _ in range(rounds if ratio > 0 else 0):
        share = np.nan_to_num(marker_cost_shares(A, B, metric, use, R))
        cand = np.flatnonzero((share.max(1) > 0.5) & (use.sum(1) > 4) & np.isfinite(cost))
        if len(cand) == 0:
            break
        frame, drop = np.nonzero(use[cand])  # one trial per (candidate, visible marker)
        masks = use[cand][frame].copy()
        masks[np.arange(len(frame)), drop] = False
        Rt, ct, _ = least_cost_rotations(A[cand][frame], B, metric, masks, start)
        ct = np.where(np.isfinite(ct), ct, np.inf)
        trial_cost = np.full((len(cand), P), np.inf)
        trial_cost[frame, drop] = ct
        best = trial_cost.argmin(1)
        changed = False
        for k, f in enumerate(cand):
            j = best[k]
            if trial_cost[k, j] < ratio * cost[f]:
                t = np.flatnonzero((frame == k) & (drop == j))[0]
                log.info("frame %d: marker %d left out of the pose fit (cost %.3g -> %.3g)", f, j,
                         cost[f], ct[t])
                use[f, j], outliers[f, j] = False, True
                R[f], cost[f] = Rt[t], ct[t]
                changed = True
        if not changed:
            break
    return outliers
