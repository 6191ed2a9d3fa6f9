"""How far apart a marker's two rays may pass before the views are said to disagree.

A sighting is checked by the other view: the ray through its pixel and the ray through the other
view's pixel of the same marker must (nearly) meet. How near depends on the footage: on clean
640x480 frames the rays of right sightings pass a median 0.04 mm apart, under sensor noise of 32
grey levels 0.1 mm (99.9th percentile 0.55 mm), while a dot taken 8 px off in one view gives about
1 mm. A fixed limit of 2 mm lets those wrong sightings through (issue 16). The limit is therefore
measured from the sequence itself: the gap of a right sighting is the distance of its pixels
from the epipolar line, about a half-normal variable, whose median is 0.674 of its scale; the
limit is ``k`` times the median of the gaps seen (``k = 8`` is 5.4 scales: a right sighting
passes it but with a chance of ~1e-7 for Gaussian pixel errors), never below ``floor_px`` pixels
(for clean footage, where the median is tiny and calibration bias dominates) and never above the
fixed ``max_ray_gap``.

An error along the epipolar line does not change the gap: no two-view test sees it. For those,
:func:`lipgen.recon.viewcheck.check_views` also asks whether a lost marker explains the dot better
(depth against each marker's last accepted 3-D point). Noise 32, validation seeds 7-10 (60 frames
each), accepted sightings more than 3 px off (both views): fixed 2 mm limit 21 / 1 / 5 / 12 ->
learned limit 0 / 0 / 3 / 17 -> with the identity check 10 / 0 / 0 / 0 (the 10: a lip corner's
neighbour on the corner's dot in both views, the corner never accepted, so nothing to compare).
"""

from __future__ import annotations

import numpy as np

__all__ = ["RayGapLimit", "px_per_mm"]


def px_per_mm(cameras, point=None) -> float:
    """Pixels per millimetre at ``point (3,)`` (default the lab origin) in the view that sees it smallest.

    Parameters
    ----------
    cameras : sequence of PinholeCamera
    point : (3,) float, optional

    Returns
    -------
    float
    """
    X = np.zeros(3) if point is None else np.asarray(point, dtype=float).reshape(3)
    return float(min(c.K[0, 0] / (c.R @ X + c.t)[2] for c in cameras))


class RayGapLimit:
    """The ray-gap limit of a sequence, from the gaps of the sightings both views agreed on.

    Parameters
    ----------
    max_gap : float
        The fixed upper limit, mm (``ReconstructSettings.max_ray_gap``); also the limit until
        ``min_samples`` gaps are known.
    k : float or None
        Limit as a multiple of the median gap; None keeps the fixed limit.
    floor : float
        Least limit, mm (e.g. ``floor_px / px_per_mm``).
    min_samples : int
        Gaps needed before the median is trusted.
    """

    def __init__(self, max_gap: float, k: float | None = 8.0, floor: float = 0.0, min_samples: int = 100):
        if not (np.isfinite(max_gap) and max_gap > 0):
            raise ValueError(f"max_gap must be a positive number of mm, got {max_gap!r}")
        if k is not None and not (np.isfinite(k) and k > 0):
            raise ValueError(f"k must be positive or None, got {k!r}")
        self.max_gap, self.k, self.floor, self.min_samples = float(max_gap), k, float(floor), int(min_samples)
        self._gaps: list[np.ndarray] = []
        self._n = 0

    def add(self, gaps) -> None:
        """Record the gaps (mm, any shape; NaN ignored) of sightings kept in one frame."""
        g = np.asarray(gaps, dtype=float).ravel()
        g = g[np.isfinite(g)]
        if len(g):
            self._gaps.append(g)
            self._n += len(g)

    @property
    def n_samples(self) -> int:
        """How many gaps were recorded."""
        return self._n

    def limit(self) -> float:
        """The limit now, mm."""
        if self.k is None or self._n < self.min_samples:
            return self.max_gap
        median = float(np.median(np.concatenate(self._gaps)))
        return float(np.clip(self.k * median, min(self.floor, self.max_gap), self.max_gap))

    @classmethod
    def of_sequence(cls, gaps, max_gap: float, k: float | None = 8.0, floor: float = 0.0,
                    min_samples: int = 100) -> float:
        """The limit, mm, from all the gaps ``(F, P)`` of a sequence (NaN: not seen in both views).

        The gaps beyond ``max_gap`` are clear mis-tracks and do not count in the median.
        """
        g = np.asarray(gaps, dtype=float)
        lim = cls(max_gap, k, floor, min_samples)
        lim.add(g[np.isfinite(g) & (g <= max_gap)])
        return lim.limit()
