"""The subject's motion statistics that decide Table 5.1's x-y / y-z order, and the lip measures
that published kinematics report.

Table 5.1's last two rows estimate the whole lip from the x-y (frontal view) or the y-z (profile
view) displacements of the 16 markers. With no measurement noise, an LLSE's error on the hidden
DOFs is the conditional variance of those DOFs given the observed ones: z given x-y for the
frontal view, x given y-z for the profile. This module measures those conditional variances on
the truth subject's own marker (ink dot) motion, without rendering, tracking or reaches:

- :func:`dot_motion`: the dots' true displacements (model frame, no head motion) of a preset's
  subject and motion, optionally with groups of sources switched off (:data:`SOURCE_GROUPS`);
- :func:`view_statistics`: per-axis variances and the conditional (LLSE residual) variance per
  hidden DOF of each view from a covariance, with R²;
- :func:`split_errors`: the same with the sample covariance of the first ``n_train`` frames,
  scored on the rest (Table 5.1's split, at the markers);
- :func:`lip_measures`: mouth width (corner to corner), midline opening and the midline
  protrusion of each lip over the frames, as phonetics measures them (Fromkin 1964; Abry & Boë
  1986), and their correlations.
"""

from __future__ import annotations

import numpy as np

from lipgen.subject.activation import action_index

__all__ = ["SOURCE_GROUPS", "dot_motion", "view_statistics", "split_errors", "lip_measures",
           "conditional_variance"]

SOURCE_GROUPS: dict[str, tuple[str, ...]] = {
    "jaw": ("jaw_open", "jaw_shift_left", "jaw_shift_right"),
    "protrusion": ("upper_lip_protrusion", "lower_lip_protrusion"),
    "pucker": ("pucker_left", "pucker_right"),
    "funneler": ("funneler_left", "funneler_right"),
    "roll_in": ("upper_lip_roll_in", "lower_lip_roll_in"),
    "press": ("lip_press_left", "lip_press_right"),
    "corners": ("lip_corner_puller_left", "lip_corner_puller_right", "lip_stretcher_left",
                "lip_stretcher_right", "lip_corner_depressor_left", "lip_corner_depressor_right"),
    "raiser": ("upper_lip_raiser_left", "upper_lip_raiser_right"),
    "lower_depressor": ("lower_lip_depressor_left", "lower_lip_depressor_right"),
    "residual": (),
}
"""Groups of the independent sources (:data:`lipgen.subject.independent.INDEPENDENT_SOURCES`)
that :func:`dot_motion` can switch off; ``residual`` is the stochastic residual deformation."""

_VIEWS = {"xy": ((0, 1), (2,)), "yz": ((1, 2), (0,))}  # view -> (observed axes, hidden axes)


def dot_motion(seed: int, n_frames: int = 150, preset: str = "default", subject_seed: int | None = None,
               drop: tuple[str, ...] = (), subject=None) -> np.ndarray:
    """(F, 16, 3) true displacements of the subject's ink dots from their rest, model frame, mm.

    The motion of :func:`lipgen.experiments.table51_protocol._motion` for motion seed ``seed``
    (the subject's stiffness and gains are drawn from ``seed`` too, as in the experiment),
    without head motion or measurement noise. ``drop`` names groups of :data:`SOURCE_GROUPS`
    whose activations are set to 0 (``"residual"``: no residual deformation).
    """
    from lipgen.experiments.table51_protocol import Table51Settings, _motion, make_subject
    from lipgen.subject.motion import simulate

    unknown = [g for g in drop if g not in SOURCE_GROUPS]
    if unknown:
        raise ValueError(f"unknown source group(s) {unknown}; the groups are {', '.join(SOURCE_GROUPS)}")
    s = Table51Settings(n_frames=max(int(n_frames), 3), n_train=2, n_modes=1, seed=int(seed), preset=preset,
                        subject_seed=subject_seed)
    subject = make_subject(s) if subject is None else subject
    acts, residual = _motion(s, subject, int(n_frames), int(seed))
    acts = np.array(acts)
    for group in drop:
        for name in SOURCE_GROUPS[group]:
            acts[:, action_index(name)] = 0.0
    motion = simulate(subject, acts)
    V = motion.vertices if residual is None or "residual" in drop else motion.vertices + residual
    from dataclasses import replace

    moved = replace(motion, vertices=V)
    return moved.markers - moved.rest_markers


def _axis_dofs(n_points: int, axes) -> np.ndarray:
    return np.array([3 * p + a for p in range(n_points) for a in axes], int)


def conditional_variance(cov: np.ndarray, observed: np.ndarray, hidden: np.ndarray) -> float:
    """Mean over ``hidden`` DOFs of their variance given the ``observed`` DOFs (mm²): the LLSE's
    expected squared error per hidden DOF when ``cov`` (D, D) is the true covariance."""
    S_oo = cov[np.ix_(observed, observed)]
    S_ho = cov[np.ix_(hidden, observed)]
    resid = cov[np.ix_(hidden, hidden)] - S_ho @ np.linalg.pinv(S_oo, rcond=1e-10, hermitian=True) @ S_ho.T
    return float(np.trace(resid) / len(hidden))


def view_statistics(D: np.ndarray) -> dict:
    """Per-axis variance and each view's conditional variance for dot displacements ``D`` (F, P, 3).

    Returns
    -------
    dict
        ``var``: {x, y, z} mean variance per DOF over the frames (mm²); for each view ``xy`` and
        ``yz``: ``residual`` (the hidden axis's conditional variance per DOF given the view, mm²)
        and ``r2`` (1 - residual / the hidden axis's variance); ``ratio`` = xy residual / yz
        residual (what Table 5.1's x-y / y-z ratio is without noise).
    """
    D = np.asarray(D, float)
    if D.ndim != 3 or D.shape[2] != 3 or D.shape[0] < 3:
        raise ValueError(f"D must be (F, P, 3) displacements with F >= 3, got shape {D.shape}")
    F, P, _ = D.shape
    cov = np.cov(D.reshape(F, -1), rowvar=False)
    var = {ax: float(np.mean(np.diag(cov)[a::3])) for a, ax in enumerate("xyz")}
    out = {"var": var}
    for view, (obs, hid) in _VIEWS.items():
        res = conditional_variance(cov, _axis_dofs(P, obs), _axis_dofs(P, hid))
        out[view] = {"residual": res, "r2": 1.0 - res / var["xyz"[hid[0]]]}
    out["ratio"] = out["xy"]["residual"] / out["yz"]["residual"]
    return out


def split_errors(D: np.ndarray, n_train: int = 140, n_modes: int | None = None) -> dict:
    """Table 5.1's split at the dots: the LLSE from the first ``n_train`` frames' sample mean and
    covariance (its first ``n_modes`` principal directions if given), scored on the remaining
    frames: mean squared error per hidden DOF (mm²) of each view, and their ratio."""
    D = np.asarray(D, float)
    F, P, _ = D.shape
    if not 2 <= n_train < F:
        raise ValueError(f"n_train must be in [2, {F - 1}] for {F} frames, got {n_train}")
    X = D.reshape(F, -1)
    mean = X[:n_train].mean(axis=0)
    cov = np.cov(X[:n_train], rowvar=False)
    if n_modes is not None:
        w, V = np.linalg.eigh(cov)
        keep = np.argsort(w)[::-1][:n_modes]
        cov = (V[:, keep] * w[keep]) @ V[:, keep].T
    test = X[n_train:] - mean
    out = {}
    for view, (obs, hid) in _VIEWS.items():
        o, h = _axis_dofs(P, obs), _axis_dofs(P, hid)
        gain = cov[np.ix_(h, o)] @ np.linalg.pinv(cov[np.ix_(o, o)], rcond=1e-10, hermitian=True)
        out[view] = float(np.mean((test[:, h] - test[:, o] @ gain.T) ** 2))
    out["ratio"] = out["xy"] / out["yz"]
    return out


def lip_measures(D: np.ndarray, rest: np.ndarray, names) -> dict:
    """Mouth width, midline opening and protrusion over the frames, and their correlations.

    Parameters
    ----------
    D : (F, 16, 3) float
        Dot displacements (mm, model frame).
    rest : (16, 3) float
        The dots at rest (mm).
    names : sequence of str
        The 16 marker names (``mesh.marker_names``).

    Returns
    -------
    dict
        ``width``, ``opening``, ``protrusion_upper``, ``protrusion_lower``: (F,) changes from
        rest in mm (width: corner to corner along x; opening: upper minus lower midline dot along
        y; protrusion: the midline dot's z); ``ranges``: each one's 5-95 % range; ``corr``: the
        correlation of upper-lip protrusion with width and with opening across frames.
    """
    D = np.asarray(D, float)
    idx = {n: i for i, n in enumerate(names)}
    P = D + np.asarray(rest, float)[None]
    R = np.asarray(rest, float)
    width = (P[:, idx["corner_left"], 0] - P[:, idx["corner_right"], 0]) - (R[idx["corner_left"], 0]
                                                                           - R[idx["corner_right"], 0])
    opening = (P[:, idx["upper_mid"], 1] - P[:, idx["lower_mid"], 1]) - (R[idx["upper_mid"], 1]
                                                                        - R[idx["lower_mid"], 1])
    pu, pl = D[:, idx["upper_mid"], 2], D[:, idx["lower_mid"], 2]
    series = {"width": width, "opening": opening, "protrusion_upper": pu, "protrusion_lower": pl}
    ranges = {k: float(np.subtract(*np.percentile(v, [95, 5]))) for k, v in series.items()}
    corr = {"protrusion_width": float(np.corrcoef(pu, width)[0, 1]),
            "protrusion_opening": float(np.corrcoef(pu, opening)[0, 1]),
            "width_opening": float(np.corrcoef(width, opening)[0, 1])}
    return {**series, "ranges": ranges, "corr": corr}

