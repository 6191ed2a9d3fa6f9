"""How far a marker may move in 3-D between frames before its sighting is called a jump.

The ray gap (:mod:`lipgen.recon.raygap`) cannot see an error along the epipolar line: at sensor
noise 32 (seed 7, 60 frames), the nose in the mirror view jumped 22 px along its epipolar line at
frame 2 and the pair was accepted 19 times. The triangulated point then jumps in depth. This
check compares each marker's point with its last accepted one: a step (mm, over the square
root of the frames elapsed)
beyond the marker's limit takes the sighting back in both views (it shows as *rejected* in the
per-marker account, :mod:`lipgen.recon.account`), and both trackers resume from their last
accepted state.

The limit is learned from the sequence, like the ray-gap limit and without truth: ``k`` times a
robust scale (the ``quantile`` of the marker's accepted steps), never below ``floor`` mm, and
``max_step`` until ``min_samples`` steps of that marker are known. A marker's own steps set its
limit, because the nose moves with the head only while the lower lip's markers move fastest
(true steps reach 6.4 mm per frame on the ``hard`` preset).

Measured (calibrate -> track -> triangulate, scored against the truth; mirror / direct px RMS over
accepted sightings, accepted share of visible sightings, accepted sightings over 3 px per view):
noise 32 seed 7 with ``DotSettings(window=1.25)``: 3.28/0.33, 69.0 %, 19/0 -> 0.29/0.30, 65.1 %,
0/0 (one jump taken back, the nose at frame 2; the lower right corner, accepted on the wrong dot
before, is now lost). With the window, hard validation seeds 7-10 and default/easy seed 7 are
unchanged (no jump found). With the plain fit, the same except hard seed 10, whose tracks start on
wrong dots: 8.53/23.8, 6.0 %, 15/27 -> 6.51/30.7, 7.5 %, 24/41 (a right sighting after a wrong
one reads as a jump until its offset, over the square root of the frames elapsed, passes).
"""

from __future__ import annotations

import numpy as np

__all__ = ["StepLimit"]


class StepLimit:
    """Per-marker limits on the 3-D step between accepted sightings, learned from the sequence.

    Parameters
    ----------
    n_markers : int
        Number of markers P.
    k : float
        Limit as a multiple of the marker's step ``quantile``.
    quantile : float
        Quantile (0-1) of the marker's accepted steps used as its scale.
    floor : float
        Least limit, mm per frame (above the triangulation noise of a still marker).
    max_step : float
        Limit, mm per frame, until ``min_samples`` steps of the marker are known (and at most).
    min_samples : int
        Steps of a marker needed before its own scale is trusted.
    """

    def __init__(self, n_markers: int, k: float = 4.0, quantile: float = 0.9, floor: float = 1.0,
                 max_step: float = 12.0, min_samples: int = 8):
        for name, value in (("k", k), ("floor", floor), ("max_step", max_step)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"StepLimit.{name} must be a positive number, got {value!r}")
        if not 0 < quantile <= 1:
            raise ValueError(f"StepLimit.quantile must be in (0, 1], got {quantile!r}")
        if floor > max_step:
            raise ValueError(f"StepLimit.floor ({floor!r}) exceeds max_step ({max_step!r})")
        self.k, self.quantile = float(k), float(quantile)
        self.floor, self.max_step = float(floor), float(max_step)
        self.min_samples = int(min_samples)
        self._steps: list[list[float]] = [[] for _ in range(int(n_markers))]

    def add(self, markers, steps) -> None:
        """Record accepted ``steps (n,)`` (mm per frame) of ``markers (n,)`` (indices)."""
        for j, s in zip(np.asarray(markers, dtype=np.int64).ravel(), np.asarray(steps, dtype=float).ravel(),
                        strict=True):
            if np.isfinite(s):
                self._steps[j].append(float(s))

    def limits(self, pooled: bool = False) -> np.ndarray:
        """(P,) float: each marker's limit now, mm per frame.

        A marker with fewer than ``min_samples`` accepted steps of its own gets ``max_step``; with
        ``pooled``, the limit of all markers' steps pooled, once they are enough (a walk back,
        :mod:`lipgen.recon.backfill`, is usually for a marker never accepted before).
        """
        fallback = self.max_step
        if pooled:
            every = [x for s in self._steps for x in s]
            if len(every) >= self.min_samples:
                fallback = self._limit(every)
        out = np.full(len(self._steps), fallback)
        for j, s in enumerate(self._steps):
            if len(s) >= self.min_samples:
                out[j] = self._limit(s)
        return out

    def _limit(self, steps) -> float:
        return float(np.clip(self.k * np.quantile(steps, self.quantile), self.floor, self.max_step))

    def check(self, points, last3d, elapsed) -> np.ndarray:
        """Which sightings jump, and learn from the others.

        Parameters
        ----------
        points : (P, 3) float
            This frame's triangulated points (NaN where not seen in both views).
        last3d : (P, 3) float
            Each marker's last accepted point (NaN where never accepted).
        elapsed : (P,) int
            Frames since that point (>= 1). The step is divided by its square root: a still marker
            (the nose) drifts like a random walk, and a wrong dot held for a few frames must not
            pass as soon as its offset is spread over them.

        Returns
        -------
        (P,) bool
            True where the step exceeds the marker's limit (the sighting is a jump).
        """
        X = np.asarray(points, dtype=float)
        L = np.asarray(last3d, dtype=float)
        if X.shape != L.shape or X.ndim != 2 or X.shape[1] != 3 or len(X) != len(self._steps):
            raise ValueError(f"points {X.shape} and last3d {L.shape} must both be ({len(self._steps)}, 3)")
        dt = np.maximum(np.asarray(elapsed, dtype=float).reshape(len(X)), 1.0)
        step = np.linalg.norm(X - L, axis=1) / np.sqrt(dt)
        known = np.isfinite(step)
        jump = known & (step > self.limits())
        ok = np.flatnonzero(known & ~jump)
        self.add(ok, step[ok])
        return jump
