"""Statistics over subject seeds for the Table 5.1 splits: means, intervals, the paired comparison.

Shared by :mod:`lipgen.experiments.table51_splits` (simulated markers) and
:mod:`lipgen.experiments.table51_pipeline` (rendered frames), which produce per-seed records of
the same shape.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ESTIMATORS", "SPLITS", "mean_interval", "paired_interval", "order", "aggregate"]

ESTIMATORS = ("modes", "full", "combined", "physics_force")
"""The four estimators compared: 10 modes, the full covariance, the combined model, the physics."""

SPLITS = ("utterance", "subject")
"""Another utterance of the training subject; another subject."""


def mean_interval(values, level: float = 0.95) -> tuple[float, float, float]:
    """(mean, low, high): the mean of ``values`` (k,) and its Student-t confidence interval."""
    from scipy import stats

    v = np.asarray(values, float)
    if v.ndim != 1 or len(v) < 2:
        raise ValueError(f"need 2 or more values for an interval, got shape {v.shape}")
    m = float(v.mean())
    half = float(stats.t.ppf(0.5 + level / 2, len(v) - 1) * v.std(ddof=1) / np.sqrt(len(v)))
    return m, m - half, m + half


def paired_interval(a, b, level: float = 0.95) -> tuple[float, float, float]:
    """(ratio, low, high): the geometric mean over seeds of ``a / b`` and its Student-t interval.

    Parameters
    ----------
    a, b : (k,) float
        Two estimators' errors (> 0) on the same k seeds (and the same test frames), k >= 2.
    level : float
        Confidence level of the interval.

    Returns
    -------
    tuple of float
        ``exp`` of the mean of ``log(a / b)`` and of its t-interval: the paired t-test on the log
        errors; an interval that excludes 1 tells the two estimators apart at ``level``.
    """
    x, y = np.asarray(a, float), np.asarray(b, float)
    if x.shape != y.shape or x.ndim != 1:
        raise ValueError(f"a and b must be two (k,) arrays of the same seeds, got shapes {x.shape} and "
                         f"{y.shape}")
    if not (np.all(x > 0) and np.all(y > 0)):
        raise ValueError("paired errors must be > 0 (a ratio of errors is compared)")
    return tuple(float(np.exp(v)) for v in mean_interval(np.log(x / y), level))


def _pairs() -> list[tuple[str, str]]:
    return [(a, b) for i, a in enumerate(ESTIMATORS) for b in ESTIMATORS[i + 1:]]


def _paired(per_seed: list, split: str, row: str, ref: str = "truth") -> dict:
    """{"a/b": (ratio, low, high)} for every pair of :data:`ESTIMATORS`."""
    return {f"{a}/{b}": paired_interval([r[split][row][a][ref] for r in per_seed],
                                        [r[split][row][b][ref] for r in per_seed]) for a, b in _pairs()}


def order(table: dict, ref: str = "truth", column: str = "modes") -> float:
    """x-y over y-z error from 16 points (> 1: the thesis's order, x-y worse; thesis: 9.4 with 10
    modes against the least-strain field)."""
    return table["xy (16 points)"][column][ref] / table["yz (16 points)"][column][ref]


def aggregate(per_seed: list, rows) -> dict:
    """Over the seeds: the mean and 95 % interval of every cell, the x-y / y-z order, the paired
    comparison, and whether the estimators separate.

    Parameters
    ----------
    per_seed : list of dict
        One record per seed: ``{split: {row: {estimator: {ref: mm²}}}, "variance_captured": float}``
        for every split of :data:`SPLITS`, estimator of :data:`ESTIMATORS` and ref ``"truth"``,
        ``"reach"``, ``"truth_relative"`` (and ``"markers"``: then the x-y / y-z order is also
        given against the measured markers); rows include ``"xy (16 points)"`` and ``"yz (16 points)"``.
    rows : sequence of str
        The rows to summarise.

    Returns
    -------
    dict
        ``"summary"``, ``"order_xy_over_yz"``, ``"paired"``, ``"distinguished"``,
        ``"variance_captured"``, ``"separated"`` (as in :func:`run_splits`' result).
    """
    summary = {}
    for split in SPLITS:
        summary[split] = {row: {col: {ref: mean_interval([r[split][row][col][ref] for r in per_seed])
                                      for ref in ("truth", "reach", "truth_relative")}
                                for col in ESTIMATORS} for row in rows}
    refs = ("truth", "reach", "markers") if all(
        "markers" in r[split][row]["modes"] for r in per_seed for split in SPLITS
        for row in ("xy (16 points)", "yz (16 points)")) else ("truth", "reach")
    orders = {split: {ref: mean_interval([order(r[split], ref) for r in per_seed]) for ref in refs}
              for split in SPLITS}
    paired = {split: {row: _paired(per_seed, split, row) for row in rows} for split in SPLITS}
    return {"summary": summary, "order_xy_over_yz": orders, "paired": paired,
            "distinguished": {split: {row: any(not lo <= 1 <= hi for _, lo, hi in paired[split][row].values())
                                      for row in rows}
                              for split in SPLITS},
            "variance_captured": mean_interval([r["variance_captured"] for r in per_seed]),
            "separated": {split: {ref: {row: _separated(summary[split][row], ref) for row in rows}
                                  for ref in ("truth", "truth_relative")} for split in SPLITS}}


def _mean_tables(tables: list) -> dict:
    """The cell-by-cell mean of tables ``{row: {column: {ref: value}}}``."""
    first = tables[0]
    return {row: {col: {ref: float(np.mean([t[row][col][ref] for t in tables])) for ref in first[row][col]}
                  for col in first[row]} for row in first}


def _separated(cells: dict, ref: str = "truth") -> bool:
    """True when the estimators' intervals do not all overlap (some pair is disjoint)."""
    iv = [cells[c][ref][1:] for c in ESTIMATORS]
    return any(a[1] < b[0] or b[1] < a[0] for i, a in enumerate(iv) for b in iv[i + 1:])
