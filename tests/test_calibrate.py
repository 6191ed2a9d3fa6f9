"""Rig calibration from ray-cast chessboard images, scored against the true rig."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from synthetic_images import render_board

from lipgen import DatasetError
from lipgen.recon.calibrate import RigCalibration, calibrate_rig, compare_to_truth, find_corners
from lipgen.rig.camera import default_rig
from lipgen.rig.target import Chessboard

pytest.importorskip("cv2")

BOARD = Chessboard(9, 6, 8.0)
FACING = np.diag([1.0, -1.0, -1.0])   # board x = world x, board y down, board z into the face


def _pose(euler_deg, centre):
    A = Rotation.from_euler("xyz", euler_deg, degrees=True).as_matrix() @ FACING
    b = np.asarray(centre, float) - A @ np.array([4 * BOARD.square, 2.5 * BOARD.square, 0.0])
    return A, b


def _sequence(n: int = 8):
    """The default rig, 8 board poses (the first faces the cameras) and the ray-cast raw frames of
    the first ``n`` of them (the first ``n`` of the 8 frames: the same draws)."""
    rig = default_rig()
    rng = np.random.default_rng(0)
    poses = [_pose([0, 0, 0], [0, 5, 0])] + [
        _pose(rng.uniform(-25, 25, 3), np.array([0, 5, 0]) + rng.uniform([-25, -20, -10], [25, 20, 10]))
        for _ in range(7)]
    raws = [rig.compose(*[render_board(cam, (9, 6), BOARD.square, p, supersample=3, rng=rng, noise=0.01)
                          for cam in rig.views]) for p in poses[:n]]
    return rig, poses, raws


@pytest.fixture(scope="module")
def sequence():
    return _sequence()


def test_corners_are_numbered_from_the_black_corner_in_every_pose():
    cam = default_rig().real_view
    for roll in (0.0, 90.0, 180.0, 250.0):
        A, b = _pose([10, -5, roll], [0, 5, 0])
        img = render_board(cam, (9, 6), BOARD.square, (A, b), supersample=3)
        uv = find_corners(img, BOARD)
        truth = cam.project(BOARD.object_points() @ A.T + b)
        assert uv is not None and np.abs(uv - truth).max() < 0.5, f"roll {roll}"
    assert find_corners(np.full((100, 80), 0.5), BOARD) is None


def _assert_recovers_the_rig(cal, rig, poses, rng):
    """8 images per view, the true rig within the bounds, and what matters downstream:
    triangulating points around the face (drawn from ``rng``)."""
    assert cal.n_images == {"virtual": 8, "real": 8, "both": 8}
    assert cal.rms["all"] < 0.2
    err = compare_to_truth(cal.in_frame(*poses[0]), rig.views)
    for view in ("virtual", "real"):
        assert np.abs(err[view]["focal_px"]).max() < 2.0
        assert err[view]["principal_point_px"] < 2.0
        assert err[view]["rotation_deg"] < 0.3
        assert err[view]["center_mm"] < 2.0
    assert err["relative"]["rotation_deg"] < 0.1 and abs(err["relative"]["baseline_mm"]) < 1.0
    X = rng.uniform([-30, -25, -15], [30, 35, 20], (300, 3))
    P, gap = cal.in_frame(*poses[0]).triangulate(rig.real_view.project(X), rig.virtual_view.project(X))
    assert np.sqrt(((P - X) ** 2).sum(1).mean()) < 0.2


def test_calibration_from_projected_corners_recovers_the_true_rig():
    """The fit of the ray-cast test below on the corners the true rig projects (0.1 px of noise)
    for the same 8 poses: the same bounds against the truth and on triangulation. With the corner
    finder's test above and the end-to-end calibration of rendered frames (tests/test_e2e.py),
    this covers the ray-cast calibration the slow set runs."""
    from lipgen.recon.calibrate import calibrate_from_corners

    rig = default_rig()
    rng = np.random.default_rng(0)
    poses = [_pose([0, 0, 0], [0, 5, 0])] + [
        _pose(rng.uniform(-25, 25, 3), np.array([0, 5, 0]) + rng.uniform([-25, -20, -10], [25, 20, 10]))
        for _ in range(7)]
    obj = BOARD.object_points()
    obs = []
    for A, b in poses:
        uv, _, inside = rig.project(obj @ A.T + b)
        assert inside.all()
        obs.append({view: rig.to_raw(view, uv[v] + rng.normal(0, 0.1, uv[v].shape))
                    for v, view in enumerate(("virtual", "real"))})
    cal = calibrate_from_corners(obs, rig, BOARD)
    _assert_recovers_the_rig(cal, rig, poses, rng)


@pytest.mark.slow(cover=("tests/test_calibrate.py::test_calibration_from_projected_corners_recovers_the_true_rig",
                         "tests/test_calibrate.py::test_corners_are_numbered_from_the_black_corner_in_every_pose",
                         "tests/test_e2e.py::test_calibration_and_triangulation_against_the_truth"))
def test_calibration_recovers_the_true_rig(sequence):
    rig, poses, raws = sequence
    cal = calibrate_rig(raws, rig, BOARD)
    _assert_recovers_the_rig(cal, rig, poses, np.random.default_rng(1))
    again = RigCalibration.from_dict(cal.to_dict())
    assert np.allclose(again.rig.camera.K, cal.rig.camera.K)


def test_calibration_bad_inputs():
    """Too few boards (3), and a reference frame without one beside 4 good ones: 5 of the
    sequence's frames are enough (ray-casting the other 3 and finding their corners cost ~2 s)."""
    rig, _, raws = _sequence(5)
    with pytest.raises(DatasetError, match=r"found whole in .* need 4"):
        calibrate_rig(raws[:3], rig, BOARD)
    blank = [np.zeros_like(raws[0])] + list(raws[1:])
    with pytest.raises(DatasetError, match="frame 0 does not show the whole board"):
        calibrate_rig(blank, rig, BOARD)
    with pytest.raises(ValueError, match="symmetric under a half turn"):
        Chessboard(8, 6, 5.0)
    with pytest.raises(ValueError, match=r"raw frame must have shape \(480, 640\)"):
        calibrate_rig([np.zeros((10, 10))] * 4, rig, BOARD)
