"""Identity checks on the markers' 3-D layout over time: a run out of place, behind, a jump, a swap.

The ray gap (:mod:`lipgen.recon.raygap`) cannot see a wrong dot that both views agree on, nor
one moved along the epipolar line: the rays still meet. On ``hard`` validation seeds 7-10 (40
frames each; truth for diagnosis only) every accepted sighting more than 3 px off was such an
identity error, and almost all sat in a *run* (frames in a row seen in both views) that was wrong
from its first frame: a lip corner whose mirror-view dot is a dark blob 6 px along the epipolar
line (its point 5-9 mm too deep), or a marker acquired on a blob about a marker spacing from its
dot. The first frame's layout check run on every frame (:mod:`lipgen.recon.recheck`) lets them
pass: its limit, 4 robust standard deviations of all residuals, is 9-23 mm on ``hard``, where
the layout at rest fits the subject's lips to about 2 mm (median) and markers are 5 mm apart.

Marker labelling in motion capture checks labels against the template's inter-marker distances
(rigid clusters, or a smoothly deforming template) and each marker's motion against its
neighbours' (a swap is a jump the neighbours do not make). :class:`MotionCheck` does both, per
marker and per run, every frame after the view checks. A marker's point is predicted from the
*established* markers (seen in both views in this frame and the one before) by the layout at
rest moved by a 3-D similarity and their smooth local offsets, its own left out
(:func:`lipgen.recon.firstframe.predict_layout`), or, with ``covariance`` (the pipeline's default,
``ReconstructSettings.motion_physics_prior``), by the model's physics prior
(:func:`lipgen.recon.layoutprior.predict_layout_physics`): with the jaw open the lower lip lies
15-25 mm from the layout at rest, and the rest layout took right lower-lip sightings back
(``renders/examples/tracking/jaw21.md``):

* **Behind the lips.** Ink lies on the lip surface; the dark blobs that pass for dots in both
  views (the mouth's inside, a lure along one view's ray) lie behind it. A point more than
  ``depth`` marker spacings behind its prediction (along the mean direction to the cameras) is
  wrong. On main's tracks of validation seeds 7-10 (accepted sightings, frames with at least 8
  established markers; truth for diagnosis only) no right sighting lay more than 3.5 mm behind
  (0 of 1846 on ``hard``, 0 of 2774 on ``default`` 7-9), 17 of the 26 wrong ones did (up to
  13.8 mm). On the later validation seeds 20-22 some right lower-lip sightings lie 4.8-5.6 mm
  behind (a mouth opening the layout predicts poorly): the limit is a compromise, 0.9 spacings.
* **A run out of place.** A run is judged once, at its first frame with at least
  ``min_established`` established markers (a run from the first frame, at the second): it is
  wrong when its point lies farther from its prediction than ``birth`` spacings and than
  ``spread`` times the established markers' median residual (right first frames on ``hard``:
  median 2.3 mm, at most 7.0 mm; wrong ones 3.5-14 mm). The layout is a weak prior on ``hard``
  subjects, hence the wide limit.
* **A jump.** A run's step from its last frame (within ``max_back`` frames) is compared with
  its neighbours' steps over the same frames: a 3-D similarity of the markers seen in both
  frames and their Gaussian-weighted residual offsets (layout distances), computed again
  without the neighbours that jumped. A jaw opening moves the lower lip's markers together and
  passes; a marker moving onto another dot makes a step its neighbours do not. The limit is
  learned from the sequence, ``jump_k`` times the median residual of the steps accepted
  (0.38-0.56 mm on the validation runs), within [``jump_floor``, ``jump_cap``] spacings.
* **A swap.** Two markers that jumped in the same frame, each onto the other's point in both
  views (the views agree on the swapped assignment), are swapped back.

A wrong sighting is taken back (:meth:`lipgen.recon.track.MarkerTracker.reject`) in the view
whose dot is far from the prediction's projection, or in both when both are. After a jump, or a
judged run going behind, the tracker resumes from its state before; when a run's identity is in
doubt from its start, its earlier sightings are taken back too and the tracker forgets the
marker (:meth:`~lipgen.recon.track.MarkerTracker.unlearn`), so that acquisition finds its dot
afresh where the layout puts it. Nothing is moved onto a dot the check chose, except in a swap.

Measured (``ReconstructSettings.motion_check`` off -> on, main 77a6b5c as the baseline in the
same run, the same cached calibrations; calibrate, track, triangulate, scored against the truth;
40 frames of ``hard``, 60 of ``default``/``easy``; accepted share of the visible sightings (wrong
ones count as accepted), accepted sightings over 3 px in both views; load 8-13):

* validation ``hard`` 7 / 8 / 9 / 10: 71.4 / 83.1 / 84.7 / 67.7 -> 71.6 / 83.1 / 84.6 / 70.8 %,
  over 3 px 7 / 1 / 1 / 35 -> 2 / 1 / 1 / 16; seeds 20 / 21 / 22 (new, for validation):
  51.9 / 39.7 / 79.6 -> 50.4 / 50.7 / 87.2 %, over 3 px 59 / 84 / 12 -> 5 / 61 / 25 (seed 22: a
  right sighting taken back in one view, the marker then acquired on a blob for 12 frames).
  In all, 199 -> 111 over 3 px, 68.3 -> 71.2 % accepted (mean).
* ``default`` 7 / 8 / 9 and ``easy`` 7: unchanged, 97.9 / 98.1 / 98.5 and 99.9 %, none over 3 px
  (no change made; the same sightings within 1.2e-8 px).
* CPU: 0.52 of 6 s on ``hard`` 7, 0.93 of 10 s on ``default`` 8 (13-15 ms a frame).
* Held out, run once after the freeze (load 12-13): ``hard`` 11 / 12 / 13 / 14 / 15 and 16 / 17
  (new): 73.2 / 63.1 / 77.9 / 85.0 / 82.2 / 42.9 / 72.8 -> 72.8 / 61.8 / 81.2 / 88.5 / 82.1 /
  49.3 / 77.2 %, over 3 px 22 / 21 / 8 / 28 / 14 / 53 / 10 -> 2 / 44 / 4 / 21 / 14 / 52 / 2; in all
  71.0 -> 73.3 % accepted, 69.4 -> 71.8 % accepted within 3 px, 156 -> 139 over 3 px (seed 12
  worse). ``default`` 11 / 12 / 13: 97.5 / 99.2 / 99.5 -> 93.3 / 99.2 / 99.5 %, none over 3 px:
  on seed 11 a wrong sighting (9 px, behind) is taken back at frame 3 and the mirror view never
  finds the marker again (a judged run resumes from its state before; the walk back had
  replaced the wrong sighting on main).
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen._validate import as_float_array
from lipgen.recon.firstframe import predict_layout
from lipgen.recon.pointreg import layout_spacing
from lipgen.recon.recheck import _take_back_run
from lipgen.recon.stereo_init import _similarity_3d
from lipgen.recon.track import LOST, MarkerTracker
from lipgen.rig.camera import VIEWS
from lipgen.rig.pinhole import triangulate

__all__ = ["MotionCheck", "frame_points"]

log = logging.getLogger(__name__)


class MotionCheck:
    """Checks the markers' runs against the 3-D layout and their steps against their neighbours'
    (see the module's description).

    Parameters
    ----------
    rest_points : (P, 3) float
        The markers at rest in the frame of the cameras, mm (NaN rows: markers without a layout).
    birth : float
        A run's point may lie this many marker spacings from its prediction.
    depth : float
        A point may lie this many marker spacings behind its prediction.
    jump_k : float
        A step's residual limit, as a multiple of the median residual of the steps accepted.
    jump_floor, jump_cap : float
        The step limit's bounds, in marker spacings (``jump_cap`` until ``min_samples`` are known).
    min_samples : int
        Step residuals needed before the learned limit is used.
    max_back : int
        A marker seen in both views within this many frames before continues its run (its step
        is checked against its neighbours' over the same frames); else a run starts.
    spread : float
        A run's point may also lie ``spread`` times the median residual of the established
        markers from its prediction (where the layout fits the frame poorly).
    min_established : int
        Fewest established markers (seen in both views in this frame and the one before) for a
        run to be judged against the layout.
    covariance : (3P, 3P) float, optional
        The layout's physics prior (:func:`lipgen.recon.layoutprior.physics_layout_covariance`):
        the layout predictions are then
        :func:`~lipgen.recon.layoutprior.predict_layout_physics`'s. None: the rest layout moved by
        a similarity and the neighbours' smoothed offsets.
    """

    def __init__(self, rest_points, birth: float = 1.5, depth: float = 0.9, jump_k: float = 6.0,
                 jump_floor: float = 0.4, jump_cap: float = 0.8, min_samples: int = 50,
                 max_back: int = 3, spread: float = 2.0, min_established: int = 8,
                 covariance=None):
        self.rest = np.asarray(rest_points, dtype=float)
        if self.rest.ndim != 2 or self.rest.shape[1] != 3 or len(self.rest) < 2:
            raise ValueError(f"rest_points must have shape (P, 3) with P >= 2, got {self.rest.shape}")
        for name, value in (("birth", birth), ("depth", depth), ("jump_k", jump_k),
                            ("jump_floor", jump_floor), ("jump_cap", jump_cap)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"MotionCheck.{name} must be a positive number, got {value!r}")
        if jump_floor > jump_cap:
            raise ValueError(f"MotionCheck.jump_floor ({jump_floor!r}) exceeds jump_cap ({jump_cap!r})")
        self.valid = np.all(np.isfinite(self.rest), axis=1)
        if self.valid.sum() < 2:
            raise ValueError("rest_points must hold at least 2 finite rows")
        self.spacing = layout_spacing(self.rest[self.valid])
        d = np.linalg.norm(self.rest[:, None] - self.rest[None], axis=2)
        np.fill_diagonal(d, np.inf)
        d[~self.valid] = np.inf
        d[:, ~self.valid] = np.inf
        self.dist = d
        # A marker far from every other (the nose) is not predicted by their offsets: not checked.
        self.checked = self.valid & (d.min(1) <= 2.5 * self.spacing)
        self.birth, self.depth = float(birth), float(depth)
        self.jump_k, self.jump_floor, self.jump_cap = float(jump_k), float(jump_floor), float(jump_cap)
        self.min_samples = int(min_samples)
        self.max_back = int(max_back)
        self.spread, self.min_established = float(spread), int(min_established)
        self.covariance = (None if covariance is None
                           else as_float_array(covariance, "covariance", (3 * len(self.rest),) * 2))
        self._last: np.ndarray | None = None
        self._since: np.ndarray | None = None
        self._samples: list[float] = []
        self.judged = np.zeros(len(self.rest), dtype=bool)   # the current run passed the layout test
        self._swapped: list[tuple[int, int]] = []
        self.resid: list[np.ndarray] = []          # per frame: layout residual of the checked (mm), NaN else
        # Each change: (frame, marker, kind, views, the sightings (2, 2) before); kind is "first"
        # (a run's first frame), "run" (a run from its start), "behind", "jump" or "swap".
        self.changes: list[tuple[int, int, str, tuple[int, ...], np.ndarray]] = []

    def jump_limit(self) -> float:
        """The step residual limit now, mm."""
        if len(self._samples) < self.min_samples:
            return self.jump_cap * self.spacing
        return float(np.clip(self.jump_k * np.median(self._samples), self.jump_floor * self.spacing,
                             self.jump_cap * self.spacing))

    def _step_prediction(self, before: np.ndarray, now: np.ndarray, use: np.ndarray, i: int
                         ) -> tuple[np.ndarray, float]:
        """Marker ``i``'s point now from its point before and the ``use`` markers' motion; (3,), weight."""
        o = np.flatnonzero(use)
        o = o[o != i]
        if len(o) < 4:
            return np.full(3, np.nan), 0.0
        T = _similarity_3d(before[o], now[o])
        base = before[np.r_[o, i]] @ T[:3, :3].T + T[:3, 3]
        w = np.exp(-0.5 * (self.dist[i, o] / self.spacing) ** 2)
        off = (w @ (now[o] - base[:-1])) / max(float(w.sum()), 1e-300)
        return base[-1] + off, float(w.sum())

    def step(self, trackers: list[MarkerTracker], views, cameras, last3d: np.ndarray | None = None,
             since: np.ndarray | None = None, names=None, skip=None) -> np.ndarray:
        """Check the current frame's sightings seen in both views; take back or swap the wrong ones.

        Parameters
        ----------
        trackers : (virtual, real) MarkerTracker
            After the current image's step and view checks.
        views : (virtual, real) images
            The current split images (for the templates of swapped markers).
        cameras : (virtual, real) PinholeCamera
        last3d : (P, 3) float, optional
            Each marker's last accepted point; set back for a sighting taken back.
        since : (P,) float, optional
            Frames since ``last3d``; set back with it.
        names : sequence of str, optional
            Marker names, for the log.
        skip : (P,) or (2, P) bool, optional
            Markers another check changed in this frame (not checked now).

        Returns
        -------
        (2, P) bool
            The sightings of the current frame taken back or changed, per view.
        """
        P = len(self.rest)
        k = len(trackers[0]._out) - 1
        took = np.zeros((2, P), dtype=bool)
        pts = {t: frame_points(trackers, cameras, t) for t in range(k, max(k - self.max_back, 0) - 1, -1)}
        X = pts[k]
        both = np.isfinite(X[:, 0])
        resid = np.full(P, np.nan)
        if k > 0 and (both & self.valid).sum() >= 6:
            skipped = (np.zeros(P, dtype=bool) if skip is None
                       else np.asarray(skip, dtype=bool).reshape(-1, P).any(0))
            bad = self._check(trackers, views, cameras, pts, k, resid, took, names, skipped)
            for i, vs in bad.items():
                doubt = self.changes_kind(k, i) in ("first", "run")   # the identity is in doubt
                for v in vs:
                    trackers[v].reject([i])
                    if doubt:
                        trackers[v].unlearn(i)
                    took[v, i] = True
                resid[i] = np.nan
                log.info("frame %d: %s taken back in the %s view(s): out of place in 3-D", k, _name(names, i),
                         " and ".join(VIEWS[v] for v in vs))
            # A jump's marker resumes from its point before; a run's first point out of place leaves
            # the marker's identity in doubt, its earlier points too: it has none until accepted again.
            idx = np.array(sorted(bad), dtype=np.int64)
            if last3d is not None and len(idx):
                jump = np.array([self.changes_kind(k, i) in ("jump", "behind") for i in idx])
                last3d[idx] = np.nan
                if self._last is not None and jump.any():
                    last3d[idx[jump]] = self._last[idx[jump]]
                if since is not None and self._since is not None:
                    since[idx] = self._since[idx] + 1
            for a, b in self._swapped:
                if last3d is not None:
                    last3d[[a, b]] = X[[b, a]]
        self._last = None if last3d is None else last3d.copy()
        self._since = None if since is None else since.copy()
        self.resid.append(resid)
        return took

    def _check(self, trackers, views, cameras, pts, k, resid, took, names, skipped
               ) -> dict[int, tuple[int, ...]]:
        """The checks of :meth:`step` on frame ``k``; fills ``resid`` and ``took`` (swaps), returns
        the sightings to take back: {marker: views}."""
        P = len(self.rest)
        X = pts[k]
        both = np.isfinite(X[:, 0])
        uv = [trackers[v]._out[k][0] for v in range(2)]
        # Each marker's last frame seen in both views, within max_back frames (-1: none).
        last = np.full(P, -1)
        for t in sorted(pts)[:-1]:
            last[np.isfinite(pts[t][:, 0])] = t
        prev = np.isfinite(pts[k - 1][:, 0])
        est = both & prev & self.valid              # established: seen in both views now and before
        use = est if est.sum() >= 5 else both & self.valid
        model = np.where(self.valid[:, None], self.rest, 0.0)
        pred = predict_layout(model, X, use, self.spacing, self.covariance)
        # Again without the established markers out of place or behind (a wrong one among them
        # drags its neighbours' predictions).
        r = np.linalg.norm(X - pred, axis=1)
        fit = float(np.median(r[use & self.checked])) if (use & self.checked).any() else np.inf
        first_limit = max(self.birth * self.spacing, self.spread * fit)
        off = use & self.checked & ((r > first_limit)
                                    | (_behind(X, pred, cameras) > self.depth * self.spacing))
        if off.any() and (use & ~off).sum() >= 5:
            use = use & ~off
            pred = predict_layout(model, X, use, self.spacing, self.covariance)
        resid[both & self.checked] = np.linalg.norm(X - pred, axis=1)[both & self.checked]
        behind = _behind(X, pred, cameras)
        self.judged[~both & (last < 0)] = False
        self._swapped = []
        bad: dict[int, tuple[int, ...]] = {}

        def drop(i: int, kind: str, p: np.ndarray) -> None:
            bad[i] = self._views_off(cameras, p, (uv[0][i], uv[1][i]))
            log.debug("frame %d: %s %s: residual %.2f mm, behind %.2f, step residual %.2f, %d established",
                      k, _name(names, i), kind, resid[i], behind[i], tres[i], int(use.sum()))
            self.changes.append((k, i, kind, bad[i], np.stack([uv[0][i], uv[1][i]])))

        # A run's later frames (seen in both views within max_back frames): its step against its
        # neighbours' over the same frames.
        cont = both & self.checked & (last >= 0) & ~skipped
        limit = self.jump_limit()
        tpred = np.full((P, 3), np.nan)
        tres = np.full(P, np.nan)
        for _ in range(2):     # again without the neighbours that jumped
            flagged = tres > limit
            for i in np.flatnonzero(cont):
                s = int(last[i])
                ok = both & np.isfinite(pts[s][:, 0]) & self.valid & ~flagged
                p, w = self._step_prediction(pts[s], X, ok, i)
                tpred[i], tres[i] = (p, float(np.linalg.norm(X[i] - p))) if w >= 0.3 else (np.nan, np.nan)
        jumped = [int(i) for i in np.flatnonzero(tres > limit)]
        self._samples.extend(tres[cont & (last == k - 1) & (tres <= limit)].tolist())
        swapped: set[int] = set()
        for a in jumped:
            for b in jumped:
                if a < b and not {a, b} & swapped and np.linalg.norm(X[b] - tpred[a]) <= limit \
                        and np.linalg.norm(X[a] - tpred[b]) <= limit:
                    self.changes += [(k, a, "swap", (0, 1), np.stack([uv[0][a], uv[1][a]])),
                                     (k, b, "swap", (0, 1), np.stack([uv[0][b], uv[1][b]]))]
                    self._swap(trackers, views, a, b)
                    self._swapped.append((a, b))
                    took[:, [a, b]] = True
                    swapped |= {a, b}
                    log.warning("frame %d: %s and %s swapped in both views (each had jumped onto the "
                                "other's point)", k, _name(names, a), _name(names, b))
        for i in jumped:
            if i not in swapped:
                drop(i, "jump", tpred[i])
        # Behind the layout: ink lies on the lips; dark blobs behind them (the mouth's inside, or
        # a lure along one view's ray) do not. Depth is along the mean direction to the cameras.
        if use.sum() >= 5:
            for i in np.flatnonzero(both & self.checked & ~skipped):
                if i in bad or i in swapped:
                    continue
                if behind[i] > self.depth * self.spacing:
                    drop(int(i), "first" if last[i] < 0 else "behind" if self.judged[i] else "run", pred[i])
        # A run is judged against the layout at its first frame where the layout can judge it
        # (enough established markers near it): at its first frame, or later for a run from the
        # first frame or begun among too few.
        fit = float(np.median(resid[use & self.checked])) if (use & self.checked).any() else np.inf
        first_limit = max(self.birth * self.spacing, self.spread * fit)
        near_use = (self.dist[:, use] <= 2.5 * self.spacing).any(1) & (use.sum() >= self.min_established)
        for i in np.flatnonzero(both & self.checked & near_use & ~skipped & ((last < 0) | ~self.judged)):
            if i in bad or i in swapped:
                continue
            if resid[i] <= first_limit:
                self.judged[i] = True
            else:
                drop(int(i), "first" if last[i] < 0 else "run", pred[i])
        for i, vs in bad.items():
            if self.changes_kind(k, i) == "run":       # a run out of place from its start: all of it
                n = [_take_back_run(trackers[v], i, k - 1) for v in vs]
                log.warning("frame %d: %s out of place in 3-D: its run taken back in the %s view(s) (%s "
                            "sightings before this frame)", k, _name(names, i),
                            " and ".join(VIEWS[v] for v in vs), " / ".join(map(str, n)))
        return bad

    def changes_kind(self, frame: int, marker: int) -> str | None:
        """The kind of the last change of ``marker`` in ``frame`` (None: no change)."""
        for c in reversed(self.changes):
            if c[0] == frame and c[1] == marker:
                return c[2]
        return None

    @staticmethod
    def _views_off(cameras, p: np.ndarray, uv: tuple[np.ndarray, np.ndarray]) -> tuple[int, ...]:
        """The view(s) whose sighting is far from ``p``'s projection: the farther one, or both when
        the nearer is over half as far."""
        if not np.all(np.isfinite(p)):
            return (0, 1)
        e = np.array([np.linalg.norm(cameras[v].project(p[None])[0] - uv[v]) for v in range(2)])
        far = int(np.argmax(e))
        return (far,) if e[1 - far] < 0.5 * e[far] else (0, 1)

    @staticmethod
    def _swap(trackers: list[MarkerTracker], views, a: int, b: int) -> None:
        """Exchange markers ``a`` and ``b``'s current sightings in both views."""
        from lipgen.recon.dots import ink_gray

        for v in range(2):
            uv = trackers[v]._out[-1][0]
            pa, pb = uv[a].copy(), uv[b].copy()
            sa, sb = trackers[v].strength[a], trackers[v].strength[b]
            gray = ink_gray(views[v])
            trackers[v].take(a, pb, gray, sb if np.isfinite(sb) else sa)
            trackers[v].take(b, pa, gray, sa if np.isfinite(sa) else sb)


def frame_points(trackers: list[MarkerTracker], cameras, t: int) -> np.ndarray:
    """(P, 3) the markers' points in frame ``t``, NaN where a view does not see them."""
    (uv0, st0, _), (uv1, st1, _) = trackers[0]._out[t], trackers[1]._out[t]
    both = (st0 != LOST) & (st1 != LOST)
    X = np.full((len(both), 3), np.nan)
    if both.any():
        X[both] = triangulate(cameras[1], uv1[both], cameras[0], uv0[both])[0]
    return X


def _behind(X: np.ndarray, pred: np.ndarray, cameras) -> np.ndarray:
    """(P,) how far each point ``X (P, 3)`` lies behind ``pred (P, 3)``, along the mean direction
    from ``pred`` to the cameras, mm (NaN where either is)."""
    toward = sum((c.center[None] - pred) / np.linalg.norm(c.center[None] - pred, axis=1, keepdims=True)
                 for c in cameras)
    toward = toward / np.linalg.norm(toward, axis=1, keepdims=True)
    return -np.einsum("ij,ij->i", X - pred, toward)


def _name(names, i) -> str:
    return str(i) if names is None else str(names[int(i)])
