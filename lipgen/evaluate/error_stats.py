"""The tracking-error summaries every report uses (``lipgen evaluate``'s tracking table,
``lipgen experiment tracking``): one definition, so that the figures agree."""

from __future__ import annotations

import numpy as np

__all__ = ["share", "error_figures", "OVER_PX"]

OVER_PX = 3.0
"""An accepted sighting farther than this from its true projection (px) counts as wrong."""


def share(part: int, whole: int) -> float:
    """``part / whole``; NaN when ``whole`` is 0 (a share of nothing is undefined, not 0 or 1)."""
    return float(part / whole) if whole else float("nan")


def error_figures(err) -> dict:
    """RMS and 95th percentile (px) of the errors ``err`` (any shape; NaN entries skipped) and how
    many exceed :data:`OVER_PX`. With no finite error: RMS and percentile NaN, the count 0."""
    e = np.asarray(err, dtype=float).ravel()
    e = e[np.isfinite(e)]
    if not len(e):
        return {"rms_px": float("nan"), "p95_px": float("nan"), "over_3px": 0}
    return {"rms_px": float(np.sqrt(np.mean(e ** 2))), "p95_px": float(np.percentile(e, 95)),
            "over_3px": int((e > OVER_PX).sum())}
