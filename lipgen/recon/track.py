"""Marker tracking over frames by normalised correlation, with detection as the safety net.

The thesis tracked its ink dots with normalised correlation and fixed the failures by hand in a
GUI (§3). Here the GUI is replaced by two things:

* **Initialisation** (:func:`match_to_expected`): the first frame's detected dots are matched to
  where the model's markers are expected to be (e.g. their projections through the calibrated
  camera) by a robust 2-D similarity ICP with one-to-one (Hungarian) assignment.
* **Recovery**: every frame, each marker is predicted by constant velocity and searched for by
  normalised correlation of its template; the correlation peak (or the prediction, when the peak
  is weak or jumps too far) is then snapped to a detected dot by a one-to-one assignment. The
  position reported is the dot's sub-pixel centroid, so template drift does not accumulate. A
  marker with no dot in reach is marked not visible (``status = LOST``) and re-acquired, with a
  widening gate, when a dot reappears near its prediction. A lost marker is carried with its
  neighbours (a neighbour just re-acquired counts with its whole jump), and a group of markers
  that jumped together beyond the search (the lower lip dropping) is moved onto its dots by one
  shift (:func:`lipgen.recon.association.shift_group`).
* **Acquisition** (``TrackerSettings.acquire_gate``, on by default): a marker not seen yet (unmatched
  in the first frame, or its first-frame match taken back) is searched for in every later frame
  where the layout, registered to the markers seen in that frame, puts it, by the first frame's
  rules (one-to-one, unambiguous; :func:`lipgen.recon.acquire.acquire_layout`). With two views,
  an acquisition stands only when the other view confirms it
  (:func:`lipgen.recon.viewcheck.check_views`).
* **Foreshortened dots**: a dot on skin turning away from the camera (the lip corner pulled back
  in a side view) is an ellipse that the detector's roundness test rejects, and the nearest round
  blob may then be no marker at all (the dark end of the mouth opening). For a marker with no
  round dot at its correlation peak, elongated blobs near it (:func:`lipgen.recon.dots.dot_peaks`)
  become candidates: it may snap to one only where its correlation found it, and they count as
  rivals when a dot is taken by the motion prediction, so the round blob beside a foreshortened
  dot is never taken in its place.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from lipgen._validate import as_float_array
from lipgen.recon.acquire import acquire_layout
from lipgen.recon.association import (
    CORRELATION_ONLY,
    LOST,
    RECOVERED,
    TRACKED,
    assign_two_routes,
    carry_lost_markers,
    drop_merged,
    fix_order,
    predict,
    shift_group,
)
from lipgen.recon.blend import split_blobs
from lipgen.recon.blobs import blob_allowed, blob_candidates, foreshortened_dots
from lipgen.recon.correlate import correlate_near, normalized_correlation, patch_around, search_box
from lipgen.recon.dots import dot_peaks, dot_response, ink_gray, refine_peaks
from lipgen.recon.pointreg import assign
from lipgen.recon.tracks import TrackerSettings, Tracks, twin_partners

__all__ = [
    "TrackerSettings", "Tracks", "TRACKED", "RECOVERED", "CORRELATION_ONLY", "LOST",
    "normalized_correlation", "MarkerTracker", "track_markers", "twin_partners", "search_box",
]

# Per-frame status of a marker (lipgen.recon.association): TRACKED, correlation agreed with a detected
# dot; RECOVERED, correlation failed and the dot was found from the motion prediction;
# CORRELATION_ONLY, no dot detected but a confident correlation peak; LOST, not found.


class MarkerTracker:
    """Tracks markers in one view, one image at a time (so several views can run in lock-step).

    Parameters
    ----------
    initial_uv : (P, 2) float
        Marker positions in the first image, NaN for markers not found there (for example from
        :func:`~lipgen.recon.pointreg.match_to_expected` on the first image's dots).
    settings : TrackerSettings
    reference_uv : (P, 2) float, optional
        The expected layout of all markers (e.g. their projections at rest). With it, a marker
        not seen yet is searched for where the layout, aligned to the seen markers, puts it, and
        markers too close together in it to be told apart (``settings.twins``) are not tracked.
    roi_margin : float
        After the first image, dots are detected only within this many pixels of the markers'
        last known positions (the rest of the image is not searched).
    """

    def __init__(self, initial_uv, settings: TrackerSettings = TrackerSettings(), reference_uv=None,
                 roi_margin: float = 60.0):
        self.init = as_float_array(initial_uv, "initial_uv", (None, 2), finite=False)
        P = len(self.init)
        self.reference = (None if reference_uv is None
                          else as_float_array(reference_uv, "reference_uv", (P, 2)))
        self.cfg = settings
        self.roi_margin = float(roi_margin)
        self.strength = np.full(P, np.nan)           # typical darkness of each marker's dot
        self.twins = np.zeros(P, dtype=bool)
        if self.reference is not None:
            self.twins = twin_partners(self.reference, settings.twins)[0] >= 0
            self.init[self.twins] = np.nan
        self.last = self.init.copy()                  # last seen position (NaN if never seen)
        self.vel = np.zeros((P, 2))
        self.gap = np.zeros(P, dtype=np.int64)        # frames since last seen
        # Each template is a patch around the rounded centroid plus the centroid's sub-pixel offset.
        self.templates: list[tuple[np.ndarray, np.ndarray] | None] = [None] * P
        self._out: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._rejected: list[np.ndarray] = []        # per image: sightings taken back by reject()
        self.acquired = np.zeros(P, dtype=bool)      # in the last image: markers seen for the first time
        self.blobbed = np.zeros(P, dtype=bool)       # in the last image: sighted on a blob (cfg.blobs)
        # Per image: its round dots (uv, strength), for tracking a marker back (lipgen.recon.backfill);
        # None for images more than history_frames back.
        self.dot_history: list[tuple[np.ndarray, np.ndarray] | None] = []
        self.history_frames = 300
        # this image's search region (lo (2,) int, ink grey (h, w), detector response (h, w)), set
        # by _dots and read by _with_blobs in the same step
        self._region: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._before = (self.last.copy(), self.gap.copy(), list(self.templates), self.strength.copy())

    def _dots(self, gray: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """This frame's round dots (uv, strength) and elongated peaks (whole pixels, strength).

        After the first image only a region around the markers is searched.
        """
        known = np.all(np.isfinite(self.last), axis=1)
        lo = np.zeros(2, dtype=int)
        sub = gray
        box = search_box(self.last[known], self.roi_margin, gray.shape) if self._out and known.any() else None
        if box is not None:
            a, b = box
            lo, sub = a, gray[a[1]:b[1], a[0]:b[0]]
        cfg = self.cfg.dots_for(self.typical_strength(np.ones(len(self.init), dtype=bool)))
        self._region = (lo, sub, dot_response(sub, cfg))   # kept for the blob candidates
        peaks, strength, roundness = dot_peaks(sub, cfg, response=self._region[2])
        round_ = roundness >= cfg.min_roundness
        uv, keep = refine_peaks(sub, peaks[round_], cfg)
        return uv + lo, strength[round_][keep], peaks[~round_] + lo, strength[~round_]

    def _with_blobs(self, gray, dots, strength, round_, allowed, e_peaks, need, cand, guess, gates, reach):
        """The candidates with unresolved blobs near the ``need`` markers' predictions appended
        (:func:`lipgen.recon.blobs.blob_candidates`), takeable only as
        :func:`~lipgen.recon.blobs.blob_allowed` says, and by the prediction route only with
        ``blob_prediction`` (else as elongated dots). Returns (dots, strength, round_, allowed)."""
        cfg, share = self.cfg, self.cfg.blob_share
        lo, sub, response = self._region
        near = np.maximum(reach, gates)[need] * share
        b_uv, b_str = blob_candidates(sub, response, lo, cfg.dots, np.vstack([guess[need], cand[need]]),
                                      np.concatenate([near, near]), np.vstack([dots, e_peaks]), gray)
        most = np.inf if cfg.max_strength_ratio is None else cfg.max_strength_ratio
        ok = blob_allowed(b_uv, b_str, guess, cand, share * reach, share * gates, need & ~self.twins,
                          self.strength, (cfg.min_strength_ratio, most))
        return (np.vstack([dots, b_uv]), np.concatenate([strength, b_str]),
                np.r_[round_, np.full(len(b_uv), cfg.blob_prediction)], np.hstack([allowed, ok]))

    def _acquire(self, uv: np.ndarray, status: np.ndarray, dots: np.ndarray, strength: np.ndarray) -> None:
        """Take dots for markers not seen yet where the layout, registered to this image's sightings,
        puts them (``settings.acquire_gate``); updates ``uv``, ``status`` and :attr:`acquired` in place."""
        cfg = self.cfg
        self.acquired = np.zeros(len(uv), dtype=bool)
        never = ~np.all(np.isfinite(self.last), axis=1)
        if cfg.reacquire_after is not None:   # and markers lost this long after being seen
            never |= self.gap >= cfg.reacquire_after
        wanted = (status == LOST) & never & ~self.twins
        seen = np.isin(status, (TRACKED, RECOVERED))
        if cfg.acquire_gate is None or self.reference is None or not wanted.any() or seen.sum() < 3 \
                or len(dots) == 0:
            return
        free = np.linalg.norm(dots[:, None] - uv[status != LOST][None], axis=2).min(1, initial=np.inf) \
            >= cfg.dots.separation / 2
        typical = self.typical_strength(seen)
        if typical > 0:   # as dark as the markers' dots: not a texture blob, nor the mouth's inside
            r = strength / typical
            free &= (r >= cfg.min_strength_ratio) & (r <= (np.inf if cfg.max_strength_ratio is None
                                                           else cfg.max_strength_ratio))
        match = acquire_layout(self.reference, uv, seen, wanted, dots, free, cfg.acquire_gate,
                               cfg.acquire_ratio)
        got = match >= 0
        uv[got], status[got] = dots[match[got]], RECOVERED
        self.acquired = got

    def step(self, image) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Track into the next image; returns this frame's ``(uv (P, 2), status (P,), score (P,))``."""
        cfg, P = self.cfg, len(self.init)
        self.acquired = np.zeros(P, dtype=bool)
        self.blobbed = np.zeros(P, dtype=bool)
        if self._out:
            # Carried only now, after any outside check took back sightings of the last image:
            # a wrong dot's jump must not drag its lost neighbours along.
            prev_uv, prev_status, _ = self._out[-1]
            carry_lost_markers(self.last, self._before[0], prev_uv, prev_status != LOST)
        self._before = (self.last.copy(), self.gap.copy(), list(self.templates), self.strength.copy())
        gray = ink_gray(image)
        dots, strength, e_peaks, e_strength = self._dots(gray)
        self.dot_history.append((dots, strength))
        if len(self.dot_history) > self.history_frames:
            self.dot_history[-self.history_frames - 1] = None
        uv = np.full((P, 2), np.nan)
        status = np.full(P, LOST, dtype=np.int8)
        score = np.full(P, np.nan)
        first = not self._out
        shifted = np.zeros(P, dtype=bool)
        n_top = len(dots)   # dots from here on are blobs (cfg.blobs)
        if first:
            seen = np.all(np.isfinite(self.init), axis=1)
            # Snap the given positions to this frame's dots so every position is a centroid.
            snap = assign(self.init, dots, np.where(seen, cfg.gate, 0.0))
            uv[seen] = self.init[seen]
            uv[snap >= 0] = dots[snap[snap >= 0]]
            status[seen] = TRACKED
        else:
            gap = self.gap
            layout = self.reference if cfg.acquire_gate is None else None    # else: _acquire
            pred = predict(self.last, self.vel, gap, layout, dots, cfg.recovery_gate)
            pred, shifted = shift_group(pred, dots, cfg.recovery_gate, cfg.gate, 3 * cfg.recovery_gate)
            cand, gates, corr_ok = pred.copy(), np.zeros(P), np.zeros(P, dtype=bool)
            for i in np.flatnonzero(np.all(np.isfinite(pred), axis=1)):
                gates[i] = cfg.recovery_gate + cfg.gate * min(gap[i], 3)
                if self.templates[i] is None:
                    continue
                patch, offset = self.templates[i]
                radius = cfg.search_radius + int(np.ceil(cfg.gate * min(gap[i], 3)))
                peak, score[i] = correlate_near(gray, patch, pred[i], radius, cfg.motion_penalty)
                peak = peak + offset
                if score[i] >= cfg.min_correlation and np.linalg.norm(peak - pred[i]) <= cfg.max_jump:
                    cand[i], corr_ok[i], gates[i] = peak, True, cfg.gate
            # A marker coming back after a loss must pass the unambiguity test even when the
            # correlation found a peak: its template may be stale and its neighbours look alike.
            # A peak with no dot at it is the skin where the dot was; the prediction, carried
            # with the neighbours, is the better guess then.
            back = (gap > 0) | shifted
            # A blob shared by neighbours' predictions (merged in the blur) is split by a joint
            # fit of their dots (lipgen.recon.blend).
            plain = dots, strength               # acquisition takes only detected dots
            if cfg.blend:
                dots, strength, e_kept = split_blobs(gray, dots, strength, e_peaks, e_strength, pred,
                                                     cfg.dots.sigma, cfg.gate)
                e_peaks, e_strength = e_peaks[e_kept], e_strength[e_kept]
            d0 = (np.linalg.norm(cand[:, None] - dots[None], axis=2).min(1) if len(dots)
                  else np.full(P, np.inf))
            guess = np.where((back & corr_ok & (d0 <= cfg.gate))[:, None], cand, pred)
            reach = cfg.recovery_gate + cfg.gate * np.minimum(gap, 3)
            # A dot seen obliquely (the lip corner turning away) is elongated and fails the
            # detector's roundness test, and the nearest round blob may then be something else
            # (the dark end of the mouth opening). For markers with no round dot at their
            # correlation peak, elongated blobs near them become candidates: takeable only where
            # the correlation found them, and rivals in the unambiguity test of the prediction.
            need = np.all(np.isfinite(pred), axis=1) & ~(d0 <= cfg.gate)
            e_uv, e_idx = foreshortened_dots(gray, dots, e_peaks, np.vstack([cand[need], guess[need]]),
                                             np.concatenate([gates[need], reach[need]]), cfg.dots)
            round_ = np.r_[np.ones(len(dots), dtype=bool), np.zeros(len(e_uv), dtype=bool)]
            dots = np.vstack([dots, e_uv])
            strength = np.concatenate([strength, e_strength[e_idx]])
            # Only a dot about as dark as the marker's own will do: texture blobs are fainter
            # than ink, and the correlation may follow the skin around a hidden dot.
            dark_enough = (np.isnan(self.strength)[:, None]
                           | (strength[None, :] >= cfg.min_strength_ratio * self.strength[:, None]))
            n_top = len(dots)
            if cfg.blobs:   # dots the top-hat cannot resolve, for markers with no round dot
                dots, strength, round_, dark_enough = self._with_blobs(
                    gray, dots, strength, round_, dark_enough, e_peaks, need, cand, guess, gates, reach)
            snap, via_corr = assign_two_routes(cand, guess, dots, gates, reach, corr_ok & ~back,
                                                dark_enough, round_dots=round_)
            got = snap >= 0
            uv[got] = dots[snap[got]]
            status[got & via_corr] = TRACKED
            status[got & ~via_corr] = RECOVERED
            trust = ~got & corr_ok & (score >= cfg.confident_correlation)
            uv[trust] = cand[trust]
            status[trust] = CORRELATION_ONLY
            drop_merged(uv, status, cand, np.all(np.isfinite(pred), axis=1),
                         max(cfg.gate, cfg.dots.separation))
            self._acquire(uv, status, *plain)
        status[self.twins] = LOST
        uv[self.twins] = np.nan
        if self.reference is not None:
            fix_order(uv, status, self.reference, 4.0 * cfg.twins)
        visible = status != LOST
        for i in np.flatnonzero(visible):
            if self.gap[i] == 0 and not first and not shifted[i] and np.all(np.isfinite(self.last[i])):
                self.vel[i] = 0.5 * self.vel[i] + 0.5 * (uv[i] - self.last[i])   # damped constant velocity
            else:
                self.vel[i] = 0.0
            if status[i] != CORRELATION_ONLY:
                tpl = patch_around(gray, uv[i], cfg.template_radius).copy()
                self.templates[i] = (tpl, uv[i] - np.round(uv[i]))
        self.last[visible] = uv[visible]
        self.gap[visible] = 0
        self.gap[~visible & np.all(np.isfinite(self.last), axis=1)] += 1
        got = np.flatnonzero(visible & (status != CORRELATION_ONLY))
        if len(got) and len(dots):  # a frame-0 match made at a lowered floor may leave no dot here
            idx = np.linalg.norm(uv[got][:, None] - dots[None], axis=2).argmin(1)
            # a blob's darkness is its flank's, not learnt (looked up after fix_order's swaps)
            self.blobbed[got[idx >= n_top]] = True
            got, idx = got[idx < n_top], idx[idx < n_top]
            self.strength[got] = _darkness(self.strength[got], strength[idx])
        self._out.append((uv, status, score))
        self._rejected.append(np.zeros(P, dtype=bool))
        return uv, status, score

    @property
    def reacquired(self) -> np.ndarray:
        """(P,) bool: markers that were not seen in the image before the last one, or never before."""
        if not self._out:
            return np.zeros(len(self.init), dtype=bool)
        return (self._before[1] > 0) | self.acquired

    def typical_strength(self, seen: np.ndarray) -> float:
        """Median darkness of the ``seen`` (P,) bool markers' dots known so far (NaN: none)."""
        known = np.isfinite(self.strength) & seen
        return float(np.median(self.strength[known])) if known.any() else np.nan

    def take(self, k: int, p: np.ndarray, gray: np.ndarray, strength: float) -> None:
        """Set marker ``k``'s sighting in the last image to ``p (2,)`` from outside (a check that
        found it there), as the tracker's own step would have re-acquired it: position, no
        velocity, template from ``gray`` (the ink image), darkness ``strength``."""
        uv, status, _ = self._out[-1]
        uv[k], status[k] = p, RECOVERED
        template = (patch_around(gray, p, self.cfg.template_radius).copy(), p - np.round(p))
        self._set_state(k, p, 0, template, _darkness(self.strength[k], strength))

    def reject(self, markers) -> None:
        """Take back the last image's sightings of ``markers`` (indices): they become LOST there.

        For a check from outside, such as the other view of a calibrated rig: the markers' state
        (last position, template, darkness) is restored to what it was before that image, so a
        wrong dot taken there is not followed.
        """
        idx = np.asarray(markers, dtype=np.int64).ravel()
        if not self._out or len(idx) == 0:
            return
        last, gap, templates, strength = self._before
        uv, status, _ = self._out[-1]
        for i in idx:
            if status[i] == LOST:
                continue
            uv[i], status[i] = np.nan, LOST
            self._rejected[-1][i] = True
            self._set_state(i, last[i], gap[i] + 1 if np.all(np.isfinite(last[i])) else 0, templates[i],
                            strength[i])
            self.acquired[i] = False
            self.blobbed[i] = False

    def withdraw(self, markers) -> None:
        """Take back the last image's acquisitions of ``markers`` (indices) as :meth:`reject` does,
        but not as rejected sightings: an acquisition the other view does not confirm was a guess."""
        idx = np.asarray(markers, dtype=np.int64).ravel()
        if not self._out or len(idx) == 0:
            return
        before = self._rejected[-1][idx].copy()
        self.reject(idx)
        self._rejected[-1][idx] = before

    def forget(self, k: int, since: int) -> None:
        """Erase marker ``k``'s sightings from image ``since`` on, as never seen (not as rejected):
        a pending acquisition the other view contradicts (:mod:`lipgen.recon.pending`)."""
        if not 0 <= since < len(self._out):
            raise ValueError(f"since must index an image seen (0..{len(self._out) - 1}), got {since!r}")
        for uv, status, score in self._out[since:]:
            uv[k], status[k], score[k] = np.nan, LOST, np.nan
        self.unlearn(k)

    def unlearn(self, k: int) -> None:
        """Drop marker ``k``'s state (position, template, darkness) but not its sightings: it is
        acquired afresh, as one never seen (an identity found wrong, :mod:`lipgen.recon.motioncheck`)."""
        self._set_state(k, np.nan, 0, None, np.nan)
        self.acquired[k] = False
        last, gap, templates, strength = self._before
        last[k], gap[k], templates[k], strength[k] = np.nan, 0, None, np.nan

    def _set_state(self, k: int, last, gap: int, template, strength: float) -> None:
        """Marker ``k``'s state set from outside a step: position, frames since seen, template,
        darkness; no velocity (a sighting put, taken back or forgotten is not motion)."""
        self.last[k], self.vel[k], self.gap[k] = last, 0.0, gap
        self.templates[k], self.strength[k] = template, strength

    def tracks(self) -> Tracks:
        """Everything tracked so far."""
        if not self._out:
            raise ValueError("the tracker has seen no frames")
        uv, status, score = (np.stack(a) for a in zip(*self._out, strict=True))
        return Tracks(uv, status != LOST, status, score, np.stack(self._rejected))


def track_markers(frames: Iterable, initial_uv: np.ndarray,
                  settings: TrackerSettings = TrackerSettings(),
                  reference_uv: np.ndarray | None = None) -> Tracks:
    """Track markers through a sequence of images of one view (see :class:`MarkerTracker`).

    Parameters
    ----------
    frames : iterable of (h, w) or (h, w, 3) arrays
        The images, in order (read lazily, one at a time).
    initial_uv : (P, 2) float
        Marker positions in the first frame, NaN for markers not found there.
    settings : TrackerSettings
    reference_uv : (P, 2) float, optional
        The expected layout of all markers, to place markers not seen yet.

    Returns
    -------
    Tracks
    """
    tracker = MarkerTracker(initial_uv, settings, reference_uv)
    for image in frames:
        tracker.step(image)
    if not tracker._out:
        raise ValueError("track_markers got no frames")
    return tracker.tracks()


def _darkness(old, new):
    """The markers' running darkness: the first sighting's, then 0.8 old + 0.2 new."""
    return np.where(np.isfinite(old), 0.8 * old + 0.2 * new, new)
