"""Table 5.1 outside the training span: actions held out of training test the combined model.

Part of :func:`lipgen.experiments.table51.run_table51` (its ``"outside_span"`` figures): the modes
and the combined model are trained on clips without the held-out actions
(``Table51Settings.held_out_test``) and tested on frames that use them, over
``Table51Settings.oos_realisations`` realisations.
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen.experiments.table51_protocol import (
    SHARES,
    Table51Settings,
    _hidden,
    _independent,
    _motion,
    _score,
    _selection,
    fit_combined,
    observation_rows,
    observe,
    row_errors,
)
from lipgen.modes.combined import CombinedModel, default_residual_variance
from lipgen.modes.model import ModeModel
from lipgen.subject.motion import ACTIONS, head_motion

__all__ = ["outside_span"]

log = logging.getLogger(__name__)


def _columns(names, sides: bool = False) -> list[int]:
    """Columns of the actions ``names``, with ``sides`` also of their one-sided halves (which
    replace a two-sided action in the independent motion)."""
    from lipgen.subject.independent import BILATERAL

    return [ACTIONS.index(b) for a in names for b in (a, *(BILATERAL.get(a, ()) if sides else ()))]


def _without(acts: np.ndarray, names, sides: bool = False) -> np.ndarray:
    acts = acts.copy()
    acts[:, _columns(names, sides)] = 0.0
    return acts


def _using(acts: np.ndarray, names, n: int, threshold: float = 0.3, sides: bool = False) -> np.ndarray:
    """The first ``n`` frames in which one of ``names`` is active above ``threshold``."""
    keep = acts[:, _columns(names, sides)].max(axis=1) > threshold
    if keep.sum() < 3:
        raise ValueError(f"too few frames use {names} (found {int(keep.sum())}); simulate more frames")
    return acts[keep][:n]


def _realisation(s: Table51Settings, subject, physics, noise_var, rng, seed: int):
    """One held-out-action realisation: (model, combined models, test data, rows)."""
    rows = {k: v for k, v in observation_rows(physics.mesh).items() if "points" in k}
    T = s.held_out_test

    def session(acts, residual, sd):
        head = head_motion(len(acts), sd) if s.head else None
        return observe(subject, physics, acts, head, s.marker_noise_mm, rng, residual, s.marker_noise_px)

    sides = _independent(s)
    acts, residual = _motion(s, subject, s.n_train, seed)
    train = session(_without(acts, T, sides), residual, seed)
    model = ModeModel(s.n_modes).fit(train.reach, mesh=physics.mesh)
    combined = fit_combined(model, physics, train.reach)
    acts, residual = _motion(s, subject, 400, seed + 1)
    keep = acts[:, _columns(T, sides)].max(axis=1) > 0.3
    residual = None if residual is None else residual[keep][:s.oos_frames]
    test = session(_using(acts, T, s.oos_frames, sides=sides), residual, seed + 1)
    return model, combined, test, rows


def _versus(table: dict, column: str = "combined") -> dict:
    """{row: (column / best learned-only, column / best physics-only)} against the truth."""
    out = {}
    for row, v in table.items():
        c = v[column]["truth"]
        out[row] = (c / min(v["modes"]["truth"], v["full"]["truth"]),
                    c / min(v["physics_force"]["truth"], v["physics_energy"]["truth"]))
    return out


def outside_span(s: Table51Settings, subject, physics, noise_var, rng) -> dict:
    """The combined model on motions outside the training span: train without the held-out
    actions, test on frames that use them; the first realisation in full, then the ratios of
    ``s.oos_realisations`` realisations (other seeds).

    Parameters
    ----------
    s : Table51Settings
    subject : lipgen.subject.motion.Subject
        The truth subject (:func:`~lipgen.experiments.table51.make_subject`).
    physics : Physics
        The model's physics on ``lip_mesh(0)`` (n0 nodes).
    noise_var : float
        Marker-noise variance, mm², given to the learned and physics-only estimators.
    rng : numpy.random.Generator
        Draws the marker noise.

    Returns
    -------
    dict
        JSON-ready: the first realisation's table ``{row: {column: {ref: mm²}}}``, the test-set
        residual-share sweep ``{row: (len(SHARES),) list}``, the combined model's selection, and
        ``"realisations"``: ``{row: {"learned", "physics", ...: (oos_realisations,) list}}``, the
        combined error over the best learned-only and physics-only error.
    """
    model, combined, test, rows = _realisation(s, subject, physics, noise_var, rng, s.seed + 13)
    table = _score(model, physics, test, rows, noise_var, combined)
    cm = combined["combined"]
    unit = default_residual_variance(model, physics, 1.0, kind=cm.kind)
    sweep = {name: [row_errors(CombinedModel(model, physics, residual_variance=sh * unit, kind=cm.kind,
                                             noise_variance=cm.noise_variance_).llse(d), d,
                               test.reach, test.truth, _hidden(physics, d)) for sh in SHARES]
             for name, d in rows.items()}
    ratios = {row: {"learned": [], "physics": [], "learned_fixed": [], "physics_fixed": []} for row in rows}

    def add(tab):
        for suffix, col in (("", "combined"), ("_fixed", "combined_fixed")):
            for row, r in _versus(tab, col).items():
                ratios[row]["learned" + suffix].append(r[0])
                ratios[row]["physics" + suffix].append(r[1])

    add(table)
    for k in range(1, s.oos_realisations):
        log.info("outside the span: realisation %d of %d", k + 1, s.oos_realisations)
        m, c, t, _ = _realisation(s, subject, physics, noise_var, rng, s.seed + 13 + 1000 * k)
        cols = ("modes", "full", "physics_force", "physics_energy", "combined", "combined_fixed")
        add(_score(m, physics, t, rows, noise_var, c, cols))
    return {"held_out_test": list(s.held_out_test), "n_test_frames": len(test.goals),
            "selection": _selection(cm), "shares": list(SHARES), "table": table, "test_share_sweep": sweep,
            "variance_captured": float(np.sum(model.explained_variance_ratio_)),
            "realisations": ratios}
