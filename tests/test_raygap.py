"""The ray-gap limit learned from a sequence (lipgen.recon.raygap)."""

import numpy as np
import pytest
from synthetic_images import background, frame

from lipgen.recon.raygap import RayGapLimit, px_per_mm
from lipgen.rig.pinhole import PinholeCamera


def test_limit_is_k_medians_of_a_half_normal_gap():
    # Gaps of right sightings are |N(0, s)|: median 0.6745 s (closed form), limit k medians.
    rng = np.random.default_rng(3)
    s = 0.07
    lim = RayGapLimit(2.0, k=8.0, floor=0.0)
    lim.add(np.abs(rng.normal(0, s, 40000)))
    assert lim.limit() == pytest.approx(8.0 * 0.6745 * s, rel=0.02)


def test_limit_is_fixed_until_known_and_clipped_to_floor_and_max():
    lim = RayGapLimit(2.0, k=8.0, floor=0.3, min_samples=50)
    lim.add(np.full(49, 0.01))
    assert lim.limit() == 2.0, "too few gaps: the fixed limit"
    lim.add([0.01, np.nan])
    assert lim.n_samples == 50
    assert lim.limit() == 0.3, "8 x 0.01 mm is below the floor"
    lim.add(np.full(200, 1.0))
    assert lim.limit() == 2.0, "8 x 1 mm is above the fixed limit"
    assert RayGapLimit(2.0, k=None).limit() == 2.0
    # Over a whole sequence: NaN (not seen in both views) and gaps beyond the fixed limit do not count.
    gaps = np.full((30, 10), 0.05)
    gaps[:, 0] = np.nan
    gaps[:, 1] = 50.0
    assert RayGapLimit.of_sequence(gaps, 2.0) == pytest.approx(0.4)
    with pytest.raises(ValueError, match="max_gap"):
        RayGapLimit(np.inf)
    with pytest.raises(ValueError, match="k must"):
        RayGapLimit(2.0, k=-1.0)


def test_px_per_mm_is_focal_over_depth():
    K = np.array([[800.0, 0, 80], [0, 800.0, 60], [0, 0, 1]])
    cams = [PinholeCamera(K, np.eye(3), np.array([0, 0, z]), 160, 120) for z in (200.0, 400.0)]
    assert px_per_mm(cams) == pytest.approx(2.0)


def _two_views():
    K = np.array([[800.0, 0, 80], [0, 800.0, 60], [0, 0, 1]])
    a = np.deg2rad(20)
    Ry = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    return (PinholeCamera(K, np.eye(3), np.array([0, 0, 300.0]), 160, 120),
            PinholeCamera(K, Ry, np.array([0, 0, 300.0]), 160, 120))


def test_a_wrong_dot_within_the_fixed_gap_is_taken_back_by_the_learned_limit():
    # From frame 10 mark 0's dot is hidden in view 1 and a round blob 4 px above it (off the
    # epipolar line, which runs along the rows) takes its place. Its rays pass ~1.5 mm apart: the
    # fixed 2 mm limit accepts a sighting 4 px off; the limit learned from the right sightings
    # (a few hundredths of a mm apart, floored at 1 px) takes it back.
    from lipgen.recon.track import MarkerTracker
    from lipgen.recon.viewcheck import check_views as _check_views
    from lipgen.rig.pinhole import triangulate

    cams = _two_views()
    rng = np.random.default_rng(5)
    grid = np.array([(x, y, 0.0) for y in (-6.0, 6.0) for x in (-8.0, 0.0, 8.0)])
    t = np.arange(18)[:, None, None]
    marks = grid[None] + np.array([1.5, 1.0, 2.0]) * np.sin(0.3 * t)
    uv = np.stack([np.stack([c.project(m) for m in marks]) for c in cams])        # (2, F, P, 2)
    bases = [background((120, 160), rng) for _ in cams]
    off = np.array([0.0, -4.0])
    wrong_gap = triangulate(cams[1], uv[1, 10:, 0] + off, cams[0], uv[0, 10:, 0])[1]
    assert np.all((wrong_gap > 1.0) & (wrong_gap < 2.0)), "the blob passes the fixed limit"
    for learned in (False, True):
        limit = RayGapLimit(2.0, k=8.0, floor=1.0 / px_per_mm(cams), min_samples=30) if learned else 2.0
        trackers = [MarkerTracker(uv[v, 0]) for v in range(2)]
        for f in range(len(marks)):
            for v in range(2):
                img_uv, shown = uv[v, f].copy(), np.ones(6, dtype=bool)
                if v == 1 and f >= 10:
                    shown[0] = False
                    img_uv = np.vstack([img_uv, img_uv[0] + off])
                    shown = np.r_[shown, True]
                trackers[v].step(frame(bases[v], img_uv, rng, visible=shown))
            if f > 0:
                _check_views(trackers, cams, limit)
        tr = trackers[1].tracks()
        err = np.linalg.norm(tr.uv[10:, 0] - uv[1, 10:, 0], axis=1)
        if not learned:
            assert np.nanmin(err) > 3, "the fixed limit accepts the blob, > 3 px off"
        else:
            assert not tr.visible[10:, 0].any(), "the learned limit reports the mark lost"
            assert tr.rejected[10:, 0].any()
            for v in range(2):
                t_v = trackers[v].tracks()
                assert np.all(np.linalg.norm(t_v.uv - uv[v], axis=2)[t_v.visible] < 1.0)


def test_a_dot_another_lost_marker_explains_better_is_not_accepted_unchecked():
    # Marks 0 and 1 at one height: in both views they lie on one epipolar line, so the ray gap
    # cannot tell them apart. View 0 has lost mark 1 and gives mark 0 mark 1's dot: its rays
    # still meet view 1's mark 0, but paired with view 1's mark 1 the dot lands where mark 1
    # was, while paired with mark 0 it lands millimetres in front of where mark 0 was. It is
    # taken back. So is mark 0 when both views lost mark 1 and gave mark 0 its dot (it lands
    # where mark 1 was). A right sighting of mark 0 beside a lost mark 1 (a dot hidden in one
    # view) is kept, and so is everything when mark 1 is seen.
    from lipgen.recon.association import LOST
    from lipgen.recon.track import MarkerTracker
    from lipgen.recon.viewcheck import check_views as _check_views
    from lipgen.rig.pinhole import triangulate

    cams = _two_views()
    rng = np.random.default_rng(2)
    X = np.array([(-4.0, 0.0, 0.0), (4.0, 0.0, 0.0), (0.0, -6.0, 1.0), (0.0, 6.0, -1.0)])
    uv = np.stack([c.project(X) for c in cams])
    wrong_gap = triangulate(cams[1], uv[1, 0], cams[0], uv[0, 1])[1]
    assert wrong_gap < 0.05, "mark 1's dot in view 0 meets mark 0's ray from view 1"
    for case in ("wrong", "both wrong", "hidden", "seen"):
        trackers = [MarkerTracker(uv[v]) for v in range(2)]
        for v in range(2):
            trackers[v].step(frame(background((120, 160), rng), uv[v], rng))
        for v in range(2 if case == "both wrong" else 1):   # "both wrong": mark 1 lost in both views,
            out_uv, status, _ = trackers[v]._out[-1]        # and both give mark 0 its dot
            if case != "seen":
                out_uv[1], status[1] = np.nan, LOST
            if "wrong" in case:
                out_uv[0] = uv[v, 1]
        last3d = X + 0.3                              # where the marks were a frame ago
        _check_views(trackers, cams, 2.0, last3d)
        t0, t1 = trackers[0].tracks(), trackers[1].tracks()
        if case == "both wrong":
            assert not t0.visible[0, 0] and not t1.visible[0, 0], "taken back in both views"
            assert t0.visible[0, 2:].all() and t1.visible[0, 2:].all()
            continue
        assert t1.visible[0].all()
        if case == "wrong":
            assert not t0.visible[0, 0] and t0.rejected[0, 0], "the ambiguous sighting is taken back"
            assert t0.visible[0, 2:].all()
        else:
            assert t0.visible[0, [0, 2, 3]].all() and not t0.rejected.any()
        assert np.isfinite(last3d).all()
