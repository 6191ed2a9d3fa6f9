"""What marker tracking is set with and what it gives: :class:`TrackerSettings`, :class:`Tracks`.

Also where a run of tracks has each marker (:func:`seen`) and the runs of consecutive frames of a
mask (:func:`true_runs`), which the checks after tracking share; and the layout test for markers too
close together to be told apart (:func:`twin_partners`), which the tracker (:mod:`lipgen.recon.track`),
the twin model (:mod:`lipgen.recon.twins`) and the account of lost markers (:mod:`lipgen.recon.account`)
share.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from lipgen._validate import as_float_array
from lipgen.recon.association import LOST
from lipgen.recon.dots import DotSettings

__all__ = ["TrackerSettings", "Tracks", "twin_partners", "lowered_floor", "seen", "true_runs"]


def seen(tracks: Tracks) -> np.ndarray:
    """(F, P) bool: where ``tracks`` has the marker (not ``LOST``, a finite position)."""
    return (tracks.status != LOST) & np.all(np.isfinite(tracks.uv), axis=-1)


def true_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of each run of consecutive True in a 1-D bool array."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], np.asarray(mask).astype(np.int8), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def lowered_floor(typical: float, ratio: float, min_contrast: float, least: float) -> float | None:
    """The contrast floor of a pale view: ``ratio`` x the darkness ``typical`` of its markers' dots
    where that is under ``min_contrast`` (else None: the fixed floor stays; NaN ``typical``, not
    known yet, too), never under ``least``."""
    lowered = ratio * typical
    if not 0 < lowered < min_contrast:
        return None
    return max(lowered, least)


@dataclass(frozen=True)
class TrackerSettings:
    """Tracking parameters (pixels unless stated).

    Attributes
    ----------
    dots : DotSettings
        How the ink dots look.
    template_radius : int
        Half-size of the correlation template.
    search_radius : int
        Half-size of the correlation search window around the prediction.
    min_correlation : float
        A correlation peak below this counts as a failure.
    confident_correlation : float
        A peak at least this high is accepted even without a detected dot there.
    gate : float
        Largest distance from the correlation peak to the dot it is snapped to.
    recovery_gate : float
        Largest distance from the prediction to a dot when correlation failed; it grows by
        ``gate`` for each of the first three frames the marker has been lost.
    max_jump : float
        A correlation peak farther than this from the prediction is a failure.
    motion_penalty : float
        Correlation given up for a match at the edge of the search window (quadratic in the
        distance from the prediction); breaks ties between look-alike dots.
    min_strength_ratio : float
        A dot must be at least this fraction as dark as the marker's dot has been.
    twin_distance : float, optional
        Markers closer than this in the reference layout cannot be told apart in this view (their
        dots merge); they are never tracked there. Defaults to ``2.5 * dots.sigma``.
    acquire_gate : float, optional
        A marker not seen yet (unmatched in the first frame, or its match taken back) is searched
        for in every later frame where the layout, registered to the markers seen in that frame,
        puts it, and takes a free dot within this distance by the first frame's rules
        (:func:`lipgen.recon.acquire.acquire_layout`: one-to-one, unambiguous by
        ``acquire_ratio``, round, about as dark as the markers' dots). With two views such an
        acquisition stands only when the other view confirms it
        (:func:`lipgen.recon.viewcheck.check_views`). None: a marker not seen yet is placed by the
        local offsets of its nearest neighbours in the motion prediction and taken like a lost
        one. 6 px by default since the first frame is matched on dark dots and checked in 3-D
        (``ReconstructSettings.first_frame_dark``, ``first_frame_layout``): on ``default``
        seeds 7 / 8 / 9 and noise 32 seeds 7 / 8 (validation), with it -> without, 89.7 / 94.6 /
        92.5 / 65.3 / 79.5 % accepted against 85.4 / 94.0 / 95.6 / 66.2 / 79.5 %, 9 sightings
        over 3 px against 11. Before
        that, 6 px (the first frame's gate) was measured in
        ``ReconstructSettings.robust_first_frame``: alone it accepts 62.6 % of the validation
        sightings instead of 57.9 %, but 221 over 3 px instead of 163 (on hard seeds 8 and 10 it
        builds on wrong first-frame matches); with the robust first frame 66.7 % and 141.
    acquire_ratio : float
        Ambiguity ratio of an acquisition.
    reacquire_after : int, optional
        A marker seen before and lost for at least this many images is searched for by the layout
        as a marker not seen yet is (``acquire_gate``); None: only markers never seen. Default 1,
        with ``ReconstructSettings.motion_physics_prior`` (adopted together after a held-out check,
        ``renders/examples/tracking/jaw21.md``): fresh ``default`` 110-114 88.9 -> 93.4 % accepted,
        over 3 px 143 -> 7; fresh ``hard`` 87-90 82.9 -> 86.2 %, 42 -> 5. Alone it had lifted
        development ``default`` 1-5 (88.3 -> 94.1 %) but lost on fresh ``default`` 105-109 (score
        24389 -> 24307; ``reacquire20.md``): a marker re-acquired while the jaw opens was judged
        against the layout at rest, and right lower-lip sightings were taken back.
    max_strength_ratio : float or None
        An acquisition takes no dot more than this many times as dark as the median of the
        view's markers' dots (None: no limit): a blob much darker than ink is the mouth's inside
        at a lip corner. Of main's acquisitions on ``hard`` 7 / 8 / 10 / 21 / 22 and ``default``
        8 (validation; truth for diagnosis only), 2 of 67 right ones and 10 of 30 wrong ones
        (6 of them ``upper_corner_left`` in the mouth's corner) were more than 2x as dark. With
        it, ``hard`` 10 / 22 accepted sightings over 3 px fall from 16 / 25 to 0 / 0
        (:mod:`lipgen.recon.oneview` gives the figures).
    blend : bool
        Two or three markers whose predictions share one blob (round, or elongated: blurred
        neighbours merged) have it split by a joint fit of their dots
        (:func:`lipgen.recon.blend.split_blobs`). Calibrate, track, triangulate on ``hard``
        validation seeds 7-10 (40 frames; off -> on): 31.7 / 82.3 / 78.8 / 62.2 -> 31.7 / 83.1 /
        79.0 / 62.2 % accepted, sightings over 3 px unchanged (58 / 1 / 27 / 37); ``default``
        7-9 and ``easy`` 7 within 0.3 points, px RMS unchanged. Held out (run once): ``hard``
        11 / 14 / 15 71.5 / 82.7 / 78.4 -> 72.4 / 82.7 / 81.1 %, over 3 px 16 / 66 / 13 -> 6 /
        66 / 11.
    floor_ratio : float or None
        After the first image, a view's detector floor (``dots.min_contrast``) is lowered to this
        share of the median darkness of its markers' dots where that is lower (:meth:`dots_for`).
        None: the fixed floor. The floor is an absolute darkness; on ``hard`` 25 the mirror
        view's dots (defocused, on dark lips) reach a median of 0.095 at the true marks, and 35 %
        of them fall under 0.08, so they were never acquired
        (``renders/examples/tracking/hard15l_seed25.md``). 0.7 was chosen on the validation sets by
        within-3-px sightings minus 10 times those over 3 px (main -> 0.5 / 0.6 / 0.7): ``hard``
        25 (the diagnosis set) 35.3 -> 48.2 / 50.0 / 47.1 % accepted within 3 px, 9 -> 18 / 33 /
        12 over 3 px; ``hard`` 21 51.2 -> 58.8 / 48.8 / 51.2 %, 25 -> 53 / 59 / 25; ``hard`` 22
        85.3 -> 92.8 / 86.0 / 85.1 %, none over 3 px. At 0.7 ``hard`` 7, 8, 9, 10 and ``default``
        8 are unchanged bit for bit (a view's floor is lowered only where its markers' dots are
        paler than 0.08 / 0.7 = 0.114).
    floor_min : float
        The lowered floor never goes under this darkness. Dots the lowered floor admits feed the
        median it is taken from, so without a bound a view whose dots pale over a take could
        lower its floor step by step into the skin texture (0.04-0.08: see
        :mod:`lipgen.recon.epipolar`). A guard, not a tuned value: 0.7 x the median darkness at ``hard``
        25's true marks (0.095) is 0.067.
    blobs : bool
        A marker with no round dot within ``gate`` of where it is looked for may take a dot the
        top-hat cannot resolve (a Laplacian-of-Gaussian blob on a darker structure's flank in
        the defocused mirror, :mod:`lipgen.recon.blobs`): by the same two routes and
        unambiguity tests as a dot, if it is ``min_strength_ratio`` to ``max_strength_ratio``
        as dark as the marker's own dot (which must be known) and nearer its prediction than
        any other marker's. False: the top-hat's dots only (the old step). On by default since xc27
        (with ``dots.blob_response`` ``"hessian"``, ``ReconstructSettings.confirm_blobs`` and the
        cross-check: ``renders/examples/tracking/xc27.md``).
    blob_share : float
        Such a blob must lie within this share (0, 1] of the ``gate`` / recovery reach.
    blob_prediction : bool
        A blob may also be taken by the motion prediction (a marker coming back, or whose
        correlation failed). False: only where the marker's correlation found it in the frame
        after a sighting (held through, never re-acquired on a blob by the tracker's step; the
        epipolar recovery, ``ReconstructSettings.epipolar_blobs``, still may), as an elongated dot
        is; it still counts as a rival in the prediction's unambiguity test.
    """

    dots: DotSettings = DotSettings()
    template_radius: int = 7
    search_radius: int = 14
    min_correlation: float = 0.5
    confident_correlation: float = 0.95
    gate: float = 3.0
    recovery_gate: float = 8.0
    max_jump: float = 12.0
    motion_penalty: float = 0.3
    twin_distance: float | None = None
    min_strength_ratio: float = 0.5
    max_strength_ratio: float | None = 2.0
    acquire_gate: float | None = 6.0
    acquire_ratio: float = 0.6
    reacquire_after: int | None = 1
    blend: bool = True
    floor_ratio: float | None = 0.7
    floor_min: float = 0.05
    blobs: bool = True
    blob_share: float = 1.0
    blob_prediction: bool = True

    def __post_init__(self):
        lo, hi = self.min_strength_ratio, self.max_strength_ratio
        if not (np.isfinite(lo) and lo >= 0):
            raise ValueError(f"min_strength_ratio must be a finite number >= 0, got {lo!r}")
        if self.floor_ratio is not None and not 0 < self.floor_ratio < 1:   # also refuses NaN
            raise ValueError(f"floor_ratio must be None (the fixed floor) or in (0, 1), "
                             f"got {self.floor_ratio!r}")
        if not 0 <= self.floor_min <= self.dots.min_contrast:   # also refuses NaN
            raise ValueError(f"floor_min must be in [0, dots.min_contrast = {self.dots.min_contrast!r}], "
                             f"got {self.floor_min!r}")
        after = self.reacquire_after
        if after is not None and (isinstance(after, bool) or not isinstance(after, int | np.integer)
                                  or after < 1):
            raise ValueError(f"reacquire_after must be None (never-seen markers only) or an integer >= 1 "
                             f"(images lost), got {after!r}")
        if not isinstance(self.blobs, bool):
            raise ValueError(f"blobs must be True or False, got {self.blobs!r}")
        if not isinstance(self.blob_prediction, bool):
            raise ValueError(f"blob_prediction must be True or False, got {self.blob_prediction!r}")
        share = self.blob_share
        if isinstance(share, bool) or not isinstance(share, int | float | np.floating) or not 0 < share <= 1:
            raise ValueError(f"blob_share must be a number in (0, 1] (1: as far as a dot), got {share!r}")
        if hi is not None and not (hi >= lo):  # also refuses NaN
            raise ValueError(f"max_strength_ratio must be None (no limit) or at least min_strength_ratio "
                             f"({lo!r}), got {hi!r}")

    def dots_for(self, typical: float) -> DotSettings:
        """The detector's settings in a view whose markers' dots have darkness ``typical`` (NaN:
        not known yet): ``dots`` with its contrast floor lowered to ``floor_ratio * typical``
        where that is lower, but not under ``floor_min``."""
        floor = (None if self.floor_ratio is None
                 else lowered_floor(typical, self.floor_ratio, self.dots.min_contrast, self.floor_min))
        return self.dots if floor is None else replace(self.dots, min_contrast=floor)

    @property
    def twins(self) -> float:
        return float(self.twin_distance if self.twin_distance is not None else 2.5 * self.dots.sigma)


@dataclass(frozen=True, eq=False)
class Tracks:
    """Tracked 2-D marker positions in one view.

    Attributes
    ----------
    uv : (F, P, 2) float
        Positions (column, row) in pixels; NaN where the marker is not visible.
    visible : (F, P) bool
    status : (F, P) int8
        ``TRACKED``, ``RECOVERED``, ``CORRELATION_ONLY`` or ``LOST``.
    score : (F, P) float
        Correlation peak (NaN in the first frame and where no search was made).
    rejected : (F, P) bool, optional
        Sightings taken back by an outside check (:meth:`MarkerTracker.reject`, e.g. the other
        view disagreed); they are ``LOST`` in ``status``. None: no such record.
    """

    uv: np.ndarray
    visible: np.ndarray
    status: np.ndarray
    score: np.ndarray
    rejected: np.ndarray | None = None

    @property
    def n_frames(self) -> int:
        return self.uv.shape[0]

    @property
    def n_markers(self) -> int:
        return self.uv.shape[1]



def twin_partners(reference, threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Markers too close to a neighbour in the layout to be told apart (their dots merge).

    Parameters
    ----------
    reference : (P, 2) float
        The expected layout, pixels.
    threshold : float
        Markers nearer than this to another are twins (``TrackerSettings.twins``).

    Returns
    -------
    partner : (P,) int
        The nearest other marker of each twin, -1 for markers that are not twins.
    distance : (P,) float
        Distance to it, pixels (NaN for non-twins).
    """
    ref = as_float_array(reference, "reference", (None, 2))
    partner, dist = np.full(len(ref), -1), np.full(len(ref), np.nan)
    if len(ref) > 1:
        d = np.linalg.norm(ref[:, None] - ref[None], axis=2)
        np.fill_diagonal(d, np.inf)
        twin = d.min(1) < threshold
        partner[twin], dist[twin] = d.argmin(1)[twin], d.min(1)[twin]
    return partner, dist
