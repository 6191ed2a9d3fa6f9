"""A marker on its close neighbour's dot in both views: the neighbour's layout offset finds its own dot free.

When a marker's own dot is too faint to be found in one view, the first frame's growth or an
acquisition can give it a close neighbour's dot in both views (``hard`` 31: the bow dip on the
upper lip's middle dot, 2.7 mm below it, for 40 frames). The rays meet, and the layout at rest
predicts the pair's point within the frame's usual residual (the subject's upper lip is taller
than the model's, so the bow dip is predicted low, near the middle dot). The neighbour's own
tracker has no dot left and is lost.

The offset between two close neighbours varies far less than where the layout puts either one,
so the check compares the two readings of the dot pair ``D`` that marker ``i`` holds, with a
close neighbour ``j`` not seen in both views:

* read as ``j``'s, ``i`` lies at ``D``'s point plus the layout offset from ``j`` to ``i``
  (moved by the similarity of the frame's pairs to the layout). In some view, a round dot that
  no marker holds lies there: in the offset's direction (within ``angle``) at its length within
  a factor ``stretch`` (the lips stretch the offset between neighbours, they turn it little);
* read as ``i``'s (as tracked), ``j`` lies at ``D``'s point plus the offset from ``i`` to ``j``;
  no view has a free dot there (read the same way), and the free dot found above is not where
  the layout puts any other marker not seen in both views (it may be that marker's own).

Then ``D`` is more likely ``j``'s, and ``i``'s sighting is taken back in both views.
This runs once tracking is done, on the final tracks and each frame's dots: taken back during
tracking, right sightings lost to a false alarm were re-acquired on lures (``hard`` 21: 25 -> 67
sightings over 3 px). Nothing is moved onto another dot.
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen._validate import as_float_array
from lipgen.recon.outofplace import take_back
from lipgen.recon.pointreg import layout_spacing
from lipgen.recon.stereo_init import _similarity_3d
from lipgen.recon.tracks import Tracks
from lipgen.rig.pinhole import PinholeCamera, triangulate

__all__ = ["ShiftCheck"]

log = logging.getLogger(__name__)


class ShiftCheck:
    """Finds the markers on a close neighbour's dot, every frame (see the module's description).

    Parameters
    ----------
    rest_points : (P, 3) float
        The markers at rest in the frame of the cameras, mm (NaN rows: no layout).
    reach : float
        Close neighbours are at most this many layout spacings apart at rest. The lip corners'
        pairs (1.0 spacings) are left out by the default 0.9: the corner's fold changes their
        offsets, and on validation their take-backs were right sightings.
    stretch, angle : float
        A dot is at a predicted offset from another when its distance is within a factor
        ``stretch`` of the offset's length (px) and its direction within ``angle`` degrees.
    min_offset : float
        Views where the neighbours' offset is shorter than this (px) are not read.
    min_pairs : int
        Fewest markers seen in both views for the frame's similarity.
    """

    def __init__(
        self,
        rest_points,
        reach: float = 0.9,
        stretch: float = 2.0,
        angle: float = 30.0,
        min_offset: float = 3.0,
        min_pairs: int = 6,
    ):
        self.rest = as_float_array(rest_points, "rest_points", (None, 3), finite=False)
        for name, value in (
            ("reach", reach),
            ("stretch", stretch),
            ("angle", angle),
            ("min_offset", min_offset),
        ):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"ShiftCheck.{name} must be a positive number, got {value!r}")
        if stretch <= 1 or angle >= 90:
            raise ValueError(
                f"ShiftCheck needs stretch > 1 and angle < 90 degrees, got {stretch!r}, {angle!r}"
            )
        if int(min_pairs) != min_pairs or min_pairs < 4:
            raise ValueError(f"ShiftCheck.min_pairs must be an integer >= 4, got {min_pairs!r}")
        self.has = np.all(np.isfinite(self.rest), axis=1)
        d = np.linalg.norm(self.rest[:, None] - self.rest[None], axis=2)
        np.fill_diagonal(d, np.inf)
        d[~self.has] = np.inf
        d[:, ~self.has] = np.inf
        self.close = d <= reach * layout_spacing(self.rest[self.has])
        self.stretch, self.angle = float(stretch), float(angle)
        self.min_offset, self.min_pairs = float(min_offset), int(min_pairs)

    def frame(self, uv, seen, dots, cameras: tuple[PinholeCamera, PinholeCamera]) -> list[tuple[int, int]]:
        """One frame's markers whose dots read better as a close neighbour's.

        Parameters
        ----------
        uv : (virtual, real) (P, 2) float
            The frame's sightings.
        seen : (2, P) bool
            Where they stand.
        dots : (virtual, real) (m, 2) float
            The round dots found in each view (those no sighting holds are free).
        cameras : (virtual, real) PinholeCamera

        Returns
        -------
        list of (marker, neighbour)
            The markers to take back, each with the neighbour whose dots they hold.
        """
        seen = np.asarray(seen, dtype=bool)
        both = seen.all(0) & self.has
        lost = ~both & self.has
        if both.sum() < self.min_pairs or not (self.close[both][:, lost]).any():
            return []
        P = len(self.rest)
        X = np.full((P, 3), np.nan)
        X[both] = triangulate(cameras[1], uv[1][both], cameras[0], uv[0][both])[0]
        A = _similarity_3d(self.rest[both], X[both])[:3, :3]
        free = []
        for v in range(2):
            d, held = np.asarray(dots[v], dtype=float).reshape(-1, 2), uv[v][seen[v]]
            if len(d) and len(held):
                d = d[np.linalg.norm(d[:, None] - held[None], axis=2).min(1) >= 0.5]
            free.append(d)
        out = []
        for i in np.flatnonzero(both):
            for j in np.flatnonzero(self.close[i] & lost):
                if self._shifted(i, j, X[i], A @ (self.rest[i] - self.rest[j]), uv, free, lost, A, cameras):
                    out.append((int(i), int(j)))
                    break
        return out

    def take_back(
        self, tracks: tuple[Tracks, Tracks], dots, cameras: tuple[PinholeCamera, PinholeCamera], names=None
    ) -> tuple[tuple[Tracks, Tracks], np.ndarray]:
        """The tracks with every frame's shifted markers (:meth:`frame`) taken back in both views.

        Parameters
        ----------
        tracks : (virtual, real) Tracks
        dots : sequence of (virtual, real) dots, or None
            Per frame, the round dots found in each view
            (:attr:`lipgen.recon.track.MarkerTracker.dot_history`); frames with None are not read.
        cameras : (virtual, real) PinholeCamera
        names : sequence of str, optional
            Marker names, for the log.

        Returns
        -------
        tracks : (virtual, real) Tracks
            New tracks: the sightings taken back are NaN and ``LOST``, and marked in ``rejected``.
        taken : (F, P) bool
        """
        tv, tr = tracks
        if tv.uv.shape != tr.uv.shape or tv.uv.shape[1] != len(self.rest) or len(dots) != tv.uv.shape[0]:
            raise ValueError(
                f"tracks must both have shape (F, {len(self.rest)}, 2) and dots F entries, got "
                f"{tv.uv.shape}, {tr.uv.shape} and {len(dots)}"
            )
        taken = np.zeros(tv.visible.shape, dtype=bool)
        for t, frame_dots in enumerate(dots):
            if frame_dots is None:
                continue
            for i, j in self.frame(
                (tv.uv[t], tr.uv[t]), np.stack([tv.visible[t], tr.visible[t]]), frame_dots, cameras
            ):
                taken[t, i] = True
                log.info(
                    "frame %d: %s taken back: its dots read better as %s's, whose layout offset finds "
                    "a free dot for it",
                    t,
                    *(k if names is None else names[k] for k in (i, j)),
                )
        return take_back(tracks, taken), taken

    def _along(self, dots: np.ndarray, d: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Dots at the offset ``p - d`` from ``d``: its direction within ``angle``, its length within a
        factor ``stretch`` (the lips stretch the offset between neighbours, they turn it little)."""
        off, e = p - d, dots - d
        n, ne = np.linalg.norm(off), np.linalg.norm(e, axis=1)
        cos = (e @ off) / np.maximum(n * ne, 1e-12)
        return (ne >= n / self.stretch) & (ne <= n * self.stretch) & (cos >= np.cos(np.radians(self.angle)))

    def _shifted(self, i, j, x, step, uv, free, lost, A, cameras) -> bool:
        """Whether ``i``'s pair at ``x`` reads better as ``j``'s (``step``: the offset j -> i, mm)."""
        found = False
        others = np.flatnonzero(lost & (np.arange(len(lost)) != j))
        for v in range(2):
            d = uv[v][i]
            p_i, p_j = cameras[v].project(np.stack([x + step, x - step]))
            if len(free[v]) == 0 or min(np.linalg.norm(p_i - d), np.linalg.norm(p_j - d)) < self.min_offset:
                continue
            if self._along(free[v], d, p_j).any():
                return False  # j's own dot may be there, free
            for e in free[v][self._along(free[v], d, p_i)]:
                # Not where the layout puts another marker not seen in both views (its own dot).
                if len(others):
                    q = cameras[v].project(x + (self.rest[others] - self.rest[i]) @ A.T)
                    if any(self._along(e[None], d, qk)[0] for qk in q):
                        continue
                found = True
        return found
