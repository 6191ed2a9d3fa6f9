"""One-view acquisitions kept pending until the other view confirms or contradicts them
(:mod:`lipgen.recon.pending`)."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_images import frame, swaying_views
from test_raygap import _two_views

from lipgen.recon.pending import PendingAcquisitions
from lipgen.recon.track import LOST, MarkerTracker, TrackerSettings
from lipgen.recon.viewcheck import check_views

M, F, HIDDEN = 5, 12, 6


def _clip(pending: bool, wrong: bool = False, seed: int = 2):
    """Two views of 12 marks (3 rows of 4, 7 mm apart) swaying together. Mark M is matched in
    neither view's first frame. Its dot is hidden in view 1 until frame ``HIDDEN``, so view 0
    alone can acquire it before then. With ``wrong``, an ink blob sits 6 px below M's dot in
    view 0 in every frame (off the epipolar line, which runs along the rows; its ray passes 2 mm
    from view 1's), and M's own dot is hidden there before frame ``HIDDEN``. Returns the
    (virtual, real) tracks and the true uv (2, F, P, 2)."""
    cams = _two_views()
    rng = np.random.default_rng(seed)
    grid = np.array([(x, y, 0.0) for y in (-7.0, 0.0, 7.0) for x in (-10.5, -3.5, 3.5, 10.5)])
    uv, bases = swaying_views(cams, grid, F, rng)  # uv (2, F, P, 2)
    trackers = []
    for v in range(2):
        init = uv[v, 0].copy()
        init[M] = np.nan
        trackers.append(MarkerTracker(init, TrackerSettings(acquire_gate=6.0), reference_uv=uv[v, 0]))
    keep = PendingAcquisitions(12, max_age=10) if pending else None
    for f in range(F):
        for v in range(2):
            pts, shown = uv[v, f], np.ones(12, dtype=bool)
            if v == 1 and f < HIDDEN:
                shown[M] = False
            if v == 0 and wrong:
                pts = np.vstack([pts, pts[M] + [0.0, 6.0]])
                shown = np.r_[shown, True]
                shown[M] = f >= HIDDEN
            trackers[v].step(frame(bases[v], pts, rng, visible=shown))
        if f > 0:
            if keep is not None:
                keep.step(trackers, cams, 1.0)
            check_views(trackers, cams, 1.0)
    return [tr.tracks() for tr in trackers], uv


def test_a_right_one_view_acquisition_survives_until_the_other_view_sees_the_marker():
    tracks, uv = _clip(pending=False)
    assert not tracks[0].visible[:HIDDEN, M].any(), "withdrawn while view 1 cannot see it"
    tracks, uv = _clip(pending=True)
    assert tracks[0].visible[1:, M].all(), "kept pending in view 0 from its acquisition on"
    both = tracks[0].visible[:, M] & tracks[1].visible[:, M]
    assert both[HIDDEN:].all() and not both[:HIDDEN].any()
    for v in range(2):
        ok = tracks[v].visible[:, M]
        assert np.linalg.norm(tracks[v].uv[ok, M] - uv[v, ok, M], axis=1).max() < 0.5


def test_a_wrong_pending_acquisition_is_erased_when_the_other_view_contradicts_it():
    tracks, uv = _clip(pending=True, wrong=True)
    v0 = tracks[0]
    err = np.linalg.norm(v0.uv[:, M] - uv[0, :, M], axis=1)
    assert not np.any(v0.visible[:, M] & (err > 1.0)), "the blob's sightings are erased"
    both = v0.visible[:, M] & tracks[1].visible[:, M]
    assert not np.any(both & (err > 1.0))
    assert np.all(v0.status[:HIDDEN, M] == LOST)
    assert both[-3:].all(), "acquired afresh on its own dot"
    without, _ = _clip(pending=False, wrong=True)
    assert not without[0].visible[:HIDDEN, M].any()


def test_bad_settings_and_a_forget_out_of_range_are_refused():
    with pytest.raises(ValueError, match="max_age"):
        PendingAcquisitions(3, max_age=0)
    tr = MarkerTracker(np.zeros((2, 2)))
    with pytest.raises(ValueError, match="since"):
        tr.forget(0, 0)
