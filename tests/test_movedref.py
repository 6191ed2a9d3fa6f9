"""The identity check's moved reference (lipgen.recon.movedref, viewcheck.check_views(reference_age=))."""

import numpy as np
import pytest
from synthetic_images import background, frame

from lipgen.recon.association import LOST
from lipgen.recon.movedref import moved_reference
from lipgen.recon.track import MarkerTracker
from lipgen.recon.viewcheck import check_views
from lipgen.rig.pinhole import PinholeCamera

# Marks 0 and 1 at one height (one epipolar line in both views), seven others around them, mm.
MARKS = np.array(
    [
        (-4.0, 0.0, 0.0),
        (4.0, 0.0, 0.0),
        (0.0, -6.0, 1.0),
        (0.0, 6.0, -1.0),
        (-8.0, 6.0, 0.0),
        (8.0, -6.0, 0.0),
        (-12.0, -1.0, -2.0),
        (12.0, 1.0, -2.0),
        (0.0, -12.0, 0.0),
    ]
)


def _two_views():
    K = np.array([[800.0, 0, 80], [0, 800.0, 60], [0, 0, 1]])
    a = np.deg2rad(20)
    Ry = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    return (
        PinholeCamera(K, np.eye(3), np.array([0, 0, 300.0]), 160, 120),
        PinholeCamera(K, Ry, np.array([0, 0, 300.0]), 160, 120),
    )


def _tracked(cams, marks, seed=3):
    """Trackers that followed ``marks (F, P, 3)`` through rendered frames, all seen in both views."""
    rng = np.random.default_rng(seed)
    uv = np.stack([np.stack([c.project(m) for m in marks]) for c in cams])  # (2, F, P, 2)
    trackers = [MarkerTracker(uv[v, 0]) for v in range(2)]
    bases = [background((120, 160), rng) for _ in cams]
    for f in range(len(marks)):
        for v in range(2):
            trackers[v].step(frame(bases[v], uv[v, f], rng))
    for v in range(2):
        err = np.linalg.norm(trackers[v].tracks().uv - uv[v], axis=2)
        assert np.all(err < 0.5), "the trackers follow every mark"
    return trackers, uv


def test_a_rigid_motion_moves_the_last_point_onto_the_point_now():
    # Frame 0 at rest, frame 2 rotated 4 degrees about y and moved 3 mm: a last point from frame
    # 0 (since = 2) is carried exactly onto the mark now, from the other marks alone.
    cams = _two_views()
    a = np.deg2rad(4)
    R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    marks = np.stack([MARKS, MARKS + [0.5, 0, 0], MARKS @ R.T + [1.0, 2.0, 2.0]])
    trackers, _ = _tracked(cams, marks)
    last3d = marks[0].copy()
    now = marks[2].copy()
    now[0] = np.nan  # mark 0 is not seen now: moved from the others
    since = np.full(len(MARKS), 2.0)
    ref = moved_reference(trackers, cams, last3d, since, now)
    assert np.linalg.norm(ref[0] - marks[2, 0]) < 0.2, "onto where mark 0 is now"
    assert np.linalg.norm(last3d[0] - marks[2, 0]) > 2.5, "the last point itself is 2.5+ mm away"
    fresh = moved_reference(trackers, cams, last3d, since, now, min_age=3)
    np.testing.assert_array_equal(fresh, last3d)  # points younger than min_age are kept


def test_the_moved_reference_keeps_a_right_sighting_after_a_fast_common_motion():
    # All marks move 5 mm along x in three frames (about 4.5 px a frame). Marks 0 and 1 were last
    # accepted in frame 0 (since = 3), and mark 1 is lost in both views now. Mark 0's right sighting
    # lands 5 mm from its last point but 3 mm from mark 1's: main's check (3 times nearer its own)
    # takes it back. Judged against where the marks should be now, it is kept, while a sighting of
    # mark 0 on mark 1's dot in both views (a swap) is still taken back.
    cams = _two_views()
    step = np.array([5.0, 0.0, 0.0]) / 3
    marks = MARKS[None] + np.arange(4)[:, None, None] * step
    for case in ("right", "swapped"):
        for age in (None, 1, 2):
            trackers, uv = _tracked(cams, marks)
            for v in range(2):
                out_uv, status, _ = trackers[v]._out[-1]
                out_uv[1], status[1] = np.nan, LOST  # mark 1's dot hidden in both views
                if case == "swapped":
                    out_uv[0] = uv[v, 3, 1]
            last3d = marks[2].copy()
            last3d[:2] = marks[0, :2]  # marks 0 and 1: last accepted in frame 0
            since = np.ones(len(MARKS))
            since[:2] = 3
            check_views(trackers, cams, 2.0, last3d, since=since, reference_age=age)
            seen = [tr.tracks().visible[3] for tr in trackers]
            kept = seen[0] & seen[1]
            # the ages move on without the jump check too (steps=None): kept 1, others one more
            before = np.ones(len(MARKS))
            before[:2] = 3
            np.testing.assert_array_equal(since, np.where(kept, 1.0, before + 1))
            assert all(s[2:].all() for s in seen), f"{case}, {age}: the other marks are kept {seen}"
            if case == "swapped" or age is None:
                assert not seen[0][0] and not seen[1][0], f"{case}, reference_age {age}: taken back"
            else:
                assert seen[0][0] and seen[1][0], f"reference_age {age}: the right sighting is kept"


def test_a_frame_with_no_marker_in_both_views_ages_every_last_point():
    # Every mark lost in view 0: nothing is kept, and every last point is one frame older (the
    # early return skipped the count, so a marker lost for a while looked as fresh as before).
    cams = _two_views()
    trackers, _ = _tracked(cams, MARKS[None].repeat(2, 0))
    out_uv, status, _ = trackers[0]._out[-1]
    out_uv[:], status[:] = np.nan, LOST
    last3d, since = MARKS.copy(), np.arange(1.0, len(MARKS) + 1)
    check_views(trackers, cams, 2.0, last3d, since=since, reference_age=1)
    np.testing.assert_array_equal(since, np.arange(2.0, len(MARKS) + 2))
    np.testing.assert_array_equal(last3d, MARKS)
    check_views(trackers, cams, 2.0, None, since=since)  # without last points nothing is counted
    np.testing.assert_array_equal(since, np.arange(2.0, len(MARKS) + 2))


def test_bad_arguments_are_refused():
    from lipgen.recon.steps import ReconstructSettings

    cams = _two_views()
    trackers, _ = _tracked(cams, MARKS[None].repeat(2, 0))
    P = len(MARKS)
    with pytest.raises(ValueError, match="now must be"):
        moved_reference(trackers, cams, MARKS, np.ones(P), MARKS[:3])
    with pytest.raises(ValueError, match="min_age"):
        moved_reference(trackers, cams, MARKS, np.ones(P), MARKS, min_age=0)
    for bad in (0, 1.5, -1, True):
        with pytest.raises(ValueError, match="identity_reference_age"):
            ReconstructSettings(identity_reference_age=bad)
    assert ReconstructSettings().identity_reference_age == 1  # the frozen default (C3)
