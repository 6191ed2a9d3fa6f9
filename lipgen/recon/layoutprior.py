"""A marker's 3-D position predicted from the others with the lip physics as the prior (leave one out).

:func:`lipgen.recon.firstframe.predict_layout` moves the model's rest layout by a similarity and
adds the neighbours' smoothed offsets. Where the mouth is open, a corner marker moves with the
jaw but its neighbours along the lip line do not tell it how far. The FEM lip does: its markers'
displacements are correlated through the stiffness. Here the displacements are Gaussian with the
covariance of the physics under white forces, ``K_s⁻¹ K_s⁻ᵀ`` on the marker DOFs (the prior of the
least-norm-force reach, :meth:`lipgen.fem.Physics.reach`), and rigid points (the nose) do not
move. A marker's position comes from ``rounds`` alternations fitted to the other markers (the
similarity of the displaced layout, then the regularised LLSE of the displacements), then the LLSE
of its own displacement from theirs. The alternation is not run to convergence: the prior lets all
markers translate together, which trades against the similarity's translation, so 8 rounds (the
configuration measured in ``renders/examples/tracking/hard15k_physics_layout.md``) sit up to about
1 mm from the 200-round answer on a 3 mm displacement. A joint solve is a follow-up.
"""

from __future__ import annotations

import numpy as np

from lipgen._validate import as_float_array
from lipgen.recon.stereo_init import _similarity_3d

__all__ = ["physics_layout_covariance", "predict_layout_physics"]


def physics_layout_covariance(physics, n_rigid: int = 1) -> np.ndarray:
    """The prior covariance of the layout's displacements, normalised to a mean variance of 1.

    Parameters
    ----------
    physics : lipgen.fem.Physics
        The model's physics; its mesh's ``markers`` are the layout's first P points.
    n_rigid : int
        Points after the markers that move with the head only (the nose): zero rows and columns.

    Returns
    -------
    (3 (P + n_rigid), 3 (P + n_rigid)) float
        Node-major (x, y, z per point) covariance, ``K_s⁻¹ K_s⁻ᵀ`` on the marker DOFs, unitless.
    """
    from lipgen.fem import dofs as node_dofs

    if int(n_rigid) != n_rigid or n_rigid < 0:
        raise ValueError(f"n_rigid must be an integer >= 0 (points that move rigidly), got {n_rigid!r}")
    markers = np.asarray(physics.mesh.markers)
    d = node_dofs(markers, "xyz", physics.n_nodes)
    columns = physics.compliance_columns(d)  # (3n, 3P): K_s⁻¹ on the marker DOFs
    cov = columns.T @ columns
    cov /= float(np.mean(np.diag(cov)))
    out = np.zeros((3 * (len(markers) + int(n_rigid)),) * 2)
    out[: len(d), : len(d)] = cov
    return out


def predict_layout_physics(
    model, points, use, covariance, smoothing: float = 0.01, rounds: int = 8, spread: bool = False
):
    """Each point's 3-D position predicted from the other used points with the physics prior.

    Parameters
    ----------
    model : (P, 3) float
        The layout at rest (the model's markers, then its rigid points), mm; NaN rows (no
        layout) are predicted NaN.
    points : (P, 3) float
        The points, mm; read where ``use``.
    use : (P,) bool
        Points the prediction is made from (at least 4).
    covariance : (3P, 3P) float
        Prior covariance of the displacements from rest (:func:`physics_layout_covariance`).
    smoothing : float
        Noise variance of a point, as a fraction of the prior's mean variance: how much of the
        points' spread the similarity takes rather than the displacements (> 0).
    rounds : int
        Alternations between the similarity and the displacements (>= 1).

    spread : bool
        Also return each prediction's spread.

    Returns
    -------
    (P, 3) float
        Predicted positions (for used points, from the others); NaN where fewer than 4 others.
    (P, 3, 3) float
        With ``spread``: the covariance of each point about its prediction, in the points' frame and up to
        one common scale (the prior's, conditioned on the others, plus the point's own ``smoothing``);
        its shape says in which directions the prediction is loose. NaN where no prediction.
    """
    model = as_float_array(model, "model", (None, 3), finite=False)
    P = len(model)
    points = as_float_array(points, "points", (P, 3), finite=False)
    use = np.asarray(use, dtype=bool)
    cov = as_float_array(covariance, "covariance", (3 * P, 3 * P))
    if use.shape != (P,):
        raise ValueError(f"use must be a ({P},) bool mask, got shape {use.shape}")
    if not (np.all(np.isfinite(points[use])) and np.all(np.isfinite(model[use]))):
        raise ValueError("points and model must be finite where use is True")
    if not (np.isfinite(smoothing) and smoothing > 0):
        raise ValueError(
            f"smoothing must be > 0 (a noise variance relative to the prior's), got {smoothing!r}"
        )
    if int(rounds) != rounds or rounds < 1:
        raise ValueError(f"rounds must be an integer >= 1, got {rounds!r}")
    out = np.full((P, 3), np.nan)
    loose = np.full((P, 3, 3), np.nan)
    idx = np.flatnonzero(use)
    axes = np.arange(3)
    for i in range(P):
        others = idx[idx != i]
        if len(others) < 4:
            continue
        dof = (3 * others[:, None] + axes).ravel()
        c_oo = cov[np.ix_(dof, dof)]
        gain = np.linalg.solve(c_oo + smoothing * np.eye(len(dof)), np.eye(len(dof)))
        shift = np.zeros((len(others), 3))
        weights = np.zeros(len(dof))
        for _ in range(int(rounds)):
            T = _similarity_3d(model[others] + shift, points[others])
            back = np.linalg.solve(T[:3, :3], (points[others] - T[:3, 3]).T).T  # into the model's frame
            weights = gain @ (back - model[others]).ravel()
            shift = (c_oo @ weights).reshape(-1, 3)
        c_io = cov[np.ix_(3 * i + axes, dof)]
        out[i] = T[:3, :3] @ (model[i] + c_io @ weights) + T[:3, 3]
        if spread:
            R = T[:3, :3]
            own = cov[np.ix_(3 * i + axes, 3 * i + axes)] - c_io @ gain @ c_io.T + smoothing * np.eye(3)
            loose[i] = R @ own @ R.T
    return (out, loose) if spread else out
