"""Lens frames: a dense board filling the direct or the mirror view, so that the calibration
recovers a real lens's tangential terms (issue 15).

The corners are projected analytically through ``cv2.projectPoints`` (an implementation
independent of lipgen's) with 0.1 px of noise, on the hard preset's lens. With the both-view
boards alone, p1 and p2 are absorbed by the board poses and the principal point; with lens
frames they come back within 10 %.
"""

import numpy as np
import pytest

from lipgen.dataset.settings import PRESET_CALIB_FRAMES, PRESET_LENS_FRAMES, GenerateSettings
from lipgen.rig.camera import VIEWS, MirrorRig, default_rig
from lipgen.rig.imaging import on_mirror
from lipgen.rig.pinhole import PinholeCamera
from lipgen.rig.target import LENS_BOARD, Chessboard, board_poses, calibration_targets, lens_poses, lens_view

cv2 = pytest.importorskip("cv2")

DIST = np.array((-0.15, 0.10, 0.0012, -0.0008, 0.0))  # the hard preset's lens
EXTENT = (90.0, 110.0)                                 # the hard preset's mirror (half sizes, mm)
BOARD = Chessboard(9, 6, 8.0)


def _rig() -> MirrorRig:
    base = default_rig()
    c = base.camera
    return MirrorRig(PinholeCamera(c.K, c.R, c.t, c.width, c.height, DIST, "real"), base.mirror_normal,
                     base.mirror_offset, base.mirror_side, base.split)


def _corners(rig, poses, board, rng, noise=0.1, dist=DIST):
    """Per pose: view -> raw pixels of the whole board where the view sees it whole (OpenCV's
    projection through the lens ``dist``)."""
    cam = rig.camera
    out = []
    for P in poses:
        X = board.object_points() @ P[:3, :3].T + P[:3, 3]
        _, _, inside = rig.project(X)
        inside[0] &= on_mirror(rig, EXTENT, X)
        per = {}
        for v, view in enumerate(VIEWS):
            if inside[v].all():
                Xs = rig.reflect(X) if view == "virtual" else X  # the mirror view sees the reflection
                uv, _ = cv2.projectPoints(Xs, cv2.Rodrigues(cam.R)[0], cam.t, cam.K, dist)
                per[view] = uv.reshape(-1, 2) + noise * rng.standard_normal((len(X), 2))
        out.append(per)
    return out


def test_lens_poses_fill_the_view_they_are_for():
    rig = _rig()
    poses = lens_poses(rig, LENS_BOARD, 6, seed=3, mirror_extent=EXTENT)
    obj = LENS_BOARD.object_points()
    for i, P in enumerate(poses):
        view = lens_view(i)
        cam = rig.real_view if view == "real" else rig.virtual_view
        X = obj @ P[:3, :3].T + P[:3, 3]
        uv = cam.project(X)
        assert cam.in_view(X, 4.0).all() and (rig.mirror_distance(X) > 0).all()
        span = np.ptp(uv, axis=0) / [cam.width, cam.height]
        assert 0.55 <= span.max() <= 1.0, (i, span)  # about the drawn fill (0.7-0.95 with the quiet border)
        if view == "virtual":
            assert on_mirror(rig, EXTENT, X).all()
        assert (cam.center - X[0]) @ P[:3, 2] < 0  # the printed face toward that view's camera
    with pytest.raises(ValueError, match="lens-frame poses that fill a view"):
        lens_poses(rig, Chessboard(17, 24, 40.0), 2, seed=0)


def test_a_few_lens_frames_pin_the_tangential_terms_that_the_both_view_boards_do_not():
    """Six lens frames beside the both-view boards (the preset's 30 are the slow set's): the fit of
    mixed boards counts every image in its views, and its p1, p2 errors are at most half those of
    the both-view boards alone (about 0.2 and 0.7 of the terms here)."""
    from lipgen.recon.calibrate import calibrate_from_corners

    rig = _rig()
    rng = np.random.default_rng(11)
    both = _corners(rig, board_poses(rig, BOARD, 10, seed=4), BOARD, rng)
    lens = _corners(rig, lens_poses(rig, LENS_BOARD, 6, seed=5, mirror_extent=EXTENT), LENS_BOARD, rng)
    before = calibrate_from_corners(both, rig, BOARD, distortion="full")
    after = calibrate_from_corners(both + lens, rig, [BOARD] * len(both) + [LENS_BOARD] * len(lens),
                                   distortion="full")
    rel_before = (before.rig.camera.dist[:4] - DIST[:4]) / DIST[:4]
    rel_after = (after.rig.camera.dist[:4] - DIST[:4]) / DIST[:4]
    assert np.all(np.abs(rel_after[2:]) < 0.5 * np.abs(rel_before[2:])), (rel_before, rel_after)
    assert np.abs(rel_after[:2]).max() < 0.05, rel_after
    assert after.rms["all"] < 0.16
    assert after.n_images == {"virtual": 10 + sum("virtual" in o for o in lens),
                              "real": 10 + sum("real" in o for o in lens),
                              "both": 10 + sum(len(o) == 2 for o in lens)}


@pytest.mark.slow(cover="tests/test_lens_frames.py::"
                  "test_a_few_lens_frames_pin_the_tangential_terms_that_the_both_view_boards_do_not")
def test_lens_frames_recover_the_tangential_terms():
    from lipgen.recon.calibrate import calibrate_from_corners

    rig = _rig()
    rng = np.random.default_rng(11)
    both = _corners(rig, board_poses(rig, BOARD, 10, seed=4), BOARD, rng)
    lens = _corners(rig, lens_poses(rig, LENS_BOARD, PRESET_LENS_FRAMES, seed=5, mirror_extent=EXTENT),
                    LENS_BOARD, rng)
    before = calibrate_from_corners(both, rig, BOARD, distortion="full")
    after = calibrate_from_corners(both + lens, rig, [BOARD] * len(both) + [LENS_BOARD] * len(lens),
                                   distortion="full")
    rel_before = (before.rig.camera.dist[:4] - DIST[:4]) / DIST[:4]
    rel_after = (after.rig.camera.dist[:4] - DIST[:4]) / DIST[:4]
    assert np.abs(rel_after).max() < 0.10, rel_after
    assert np.abs(rel_before[2:]).max() > 0.10, rel_before  # without lens frames p1/p2 are not pinned
    assert after.rms["all"] < 0.16
    assert after.n_images == {"virtual": 10 + sum("virtual" in o for o in lens),
                              "real": 10 + sum("real" in o for o in lens),
                              "both": 10 + sum(len(o) == 2 for o in lens)}


def test_calibration_targets_keep_the_both_view_poses_and_settings_record_lens_frames():
    rig = _rig()
    plain = board_poses(rig, BOARD, 4, seed=np.random.default_rng([7, 1]))
    targets = calibration_targets(rig, BOARD, 4, 2, np.random.default_rng([7, 1]), EXTENT)
    assert [t[2] for t in targets] == [None] * 4 + ["real", "virtual"]
    assert all(t[0] == BOARD for t in targets[:4]) and all(t[0] == LENS_BOARD for t in targets[4:])
    np.testing.assert_array_equal(np.stack([t[1] for t in targets[:4]]), plain)
    hard = GenerateSettings.from_preset("hard")
    assert (hard.calib_frames, hard.lens_frames) == (PRESET_CALIB_FRAMES, PRESET_LENS_FRAMES)
    assert GenerateSettings.from_dict(hard.to_dict()) == hard
    assert GenerateSettings.from_preset("hard", calib_frames=10).lens_frames == 0
    assert "lens_frames" not in GenerateSettings.from_preset("easy").to_dict()  # easy's manifest as before
    with pytest.raises(ValueError, match=r"lens_frames \(4\) must leave at least one of the calib_frames"):
        GenerateSettings(calib_frames=4, lens_frames=4)
    with pytest.raises(ValueError, match=r"board must be a Chessboard or one per calibration image \(3\)"):
        from lipgen.recon.calibrate import calibrate_from_corners

        calibrate_from_corners([{}] * 3, rig, [BOARD] * 2)


@pytest.mark.render
def test_generate_writes_lens_frames_and_says_which(tmp_path):
    pytest.importorskip("lipgen.rig.render")
    from lipgen.dataset.generate import generate
    from lipgen.dataset.layout import Dataset

    s = GenerateSettings(frames=1, calib_frames=3, lens_frames=2, size=(160, 120), seed=2)
    ds = Dataset(generate(tmp_path / "ds", s, workers=1, progress=False))
    cal = ds.manifest["calibration"]
    assert ds.settings.lens_frames == 2 and cal["lens_board"]["inner_cols"] == LENS_BOARD.inner_cols
    assert [f.get("fills") for f in cal["frames"]] == [None, "real", "virtual"]
    assert ds.calibration_boards() == [Chessboard(*s.board), LENS_BOARD, LENS_BOARD]
    frames = ds.calibration()
    assert "lens_view" not in frames[0].truth
    for f, view in zip(frames[1:], ("real", "virtual"), strict=True):
        assert str(f.truth["lens_view"]) == view
        assert f.truth["in_image"][VIEWS.index(view)].all()  # the board is whole in the view it fills
        assert len(f.truth["corners_board"]) == len(LENS_BOARD.object_points())
