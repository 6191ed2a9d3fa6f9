"""The mirror's ghost in the corner fit (lipgen.recon.cornerfit, lipgen.recon.ghost), against ground truth.

Synthetic boards (exact pixel-area coverage, 8x8 supersampling) are drawn in linear light at known
sub-pixel corners, with a known ghost: the whole image again, shifted by ``delta`` and scaled by
``r``, then blurred and noisy. The plain X-junction fit is biased by the copy (every corner of a
board moves together); the fit with the ghost modelled is not, and the ghost's shift and strength
are recovered from the boards without being told.
"""

import numpy as np
import pytest

from lipgen.recon.cornerfit import fit_corners
from lipgen.recon.ghost import Ghost, estimate_ghost

cv2 = pytest.importorskip("cv2")

GHOST = (4.4, 5.8, 0.05)  # 7.3 px aside, 5 %: the hard preset's ghost
SHAPE = (6, 8)


def _board(rng, ghost, rows=6, cols=8, blur=1.2, noise=2.0, ss=8):
    """(H, W) linear image of a turned, skewed board with a white margin, and its true corners."""
    sq, ang, skew = rng.uniform(9, 13), rng.uniform(-0.4, 0.4), rng.uniform(-0.15, 0.15)
    A = sq * np.array([[np.cos(ang), -np.sin(ang + skew)], [np.sin(ang), np.cos(ang + skew)]])
    H, W = int(sq * (rows + 5)) + 30, int(sq * (cols + 5)) + 30
    origin = np.array([W / 2, H / 2]) - A @ np.array([(cols - 1) / 2, (rows - 1) / 2])
    origin = origin + rng.uniform(-0.5, 0.5, 2)
    ys, xs = np.mgrid[0:H * ss, 0:W * ss]
    P = np.stack([(xs + 0.5) / ss - 0.5, (ys + 0.5) / ss - 0.5], -1)  # pixel (0, 0) at its centre

    def render(o):
        q = (P - o) @ np.linalg.inv(A).T
        board = (q[..., 0] > -1) & (q[..., 0] < cols) & (q[..., 1] > -1) & (q[..., 1] < rows)
        black = ((np.floor(q[..., 0]) + np.floor(q[..., 1])) % 2 == 0) & board
        return 0.05 + 0.75 * (~black).reshape(H, ss, W, ss).mean((1, 3))

    img = render(origin)
    if ghost is not None:
        img = img + ghost[2] * render(origin + np.asarray(ghost[:2]))
    img = cv2.GaussianBlur(img, (0, 0), blur) + rng.normal(0, noise / 255, (H, W))
    j, i = np.mgrid[0:rows, 0:cols]
    return img, origin + np.column_stack([i.ravel(), j.ravel()]) @ A.T


def _boards(seed, ghost, n=5):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        img, truth = _board(rng, ghost)
        out.append((img, truth, truth + rng.uniform(-0.3, 0.3, truth.shape)))
    return out


def _errors(boards, ghost):
    err = [fit_corners(img, start, SHAPE, ghost=ghost)[0] - truth for img, truth, start in boards]
    rms = float(np.sqrt((np.vstack(err) ** 2).sum(1).mean()))
    worst_board_mean = float(max(np.linalg.norm(e.mean(0)) for e in err))
    return rms, worst_board_mean


def test_known_ghost_removes_the_plain_fits_bias():
    boards = _boards(1, GHOST)
    rms_plain, mean_plain = _errors(boards, None)
    rms_ghost, mean_ghost = _errors(boards, GHOST)
    assert mean_plain > 0.04, mean_plain  # the copy moves whole boards
    assert rms_ghost < 0.05 and mean_ghost < 0.015, (rms_ghost, mean_ghost)
    assert rms_ghost < 0.6 * rms_plain, (rms_ghost, rms_plain)


@pytest.mark.parametrize("ghost", [GHOST, (-6.0, 2.5, 0.03)])
def test_ghost_is_estimated_from_the_boards(ghost):
    boards = _boards(2, ghost)
    plain = [fit_corners(img, start, SHAPE)[0] for img, _, start in boards]
    est = estimate_ghost([img for img, _, _ in boards], plain, [SHAPE] * len(boards), max_shift=9)
    assert isinstance(est, Ghost)
    assert np.linalg.norm(est.shift - ghost[:2]) < 0.25, est
    assert abs(est.strength - ghost[2]) < 0.15 * ghost[2], est
    assert est.snr > 100 and est.shown, est
    rms, worst = _errors(boards, est.params)
    assert rms < 0.05 and worst < 0.02, (rms, worst)


def test_no_ghost_is_not_taken_for_one():
    """Without a ghost the estimate is weak and uncertain: below calibrate_rig's bar for modelling it."""
    boards = _boards(3, None)
    plain = [fit_corners(img, start, SHAPE)[0] for img, _, start in boards]
    est = estimate_ghost([img for img, _, _ in boards], plain, [SHAPE] * len(boards), max_shift=9)
    assert not est.shown, est


def test_ghost_bad_inputs():
    img = np.zeros((60, 60))
    with pytest.raises(ValueError, match=r"ghost must be \(dx, dy, r\) with finite values"):
        fit_corners(img, np.zeros((9, 2)), (3, 3), ghost=(1.0, 2.0))
    with pytest.raises(ValueError, match=r"0 <= r < 1, got array\(\[1. , 2. , 1.5\]\)"):
        fit_corners(img, np.zeros((9, 2)), (3, 3), ghost=(1.0, 2.0, 1.5))
    with pytest.raises(ValueError, match=r"grays, corners and grid_shapes must be equally long and not "
                                         r"empty, got 1, 2 and 1"):
        estimate_ghost([img], [np.zeros((9, 2))] * 2, [(3, 3)])
    with pytest.raises(ValueError, match=r"corners\[0\] must be \(9, 2\) for a 3x3 grid, got shape \(8, 2\)"):
        estimate_ghost([img], [np.zeros((8, 2))], [(3, 3)])
    with pytest.raises(ValueError, match=r"grays\[0\] must be an \(H, W\) image, got shape \(60, 60, 3\)"):
        estimate_ghost([np.zeros((60, 60, 3))], [np.zeros((9, 2))], [(3, 3)])
    with pytest.raises(ValueError, match=r"max_shift must be positive \(px\), got 0"):
        estimate_ghost([img], [np.zeros((9, 2))], [(3, 3)], max_shift=0)
    with pytest.raises(ValueError, match=r"too few interior corners to estimate a ghost: 1 \(need 4\)"):
        estimate_ghost([img], [np.zeros((9, 2))], [(3, 3)])


def test_find_corners_and_calibrate_name_a_bad_ghost():
    from lipgen.recon.calibrate import calibrate_rig
    from lipgen.recon.chessboard import find_corners
    from lipgen.rig.camera import default_rig
    from lipgen.rig.target import Chessboard

    with pytest.raises(ValueError, match=r"a ghost is modelled by refine='fit' only, got refine='subpix'"):
        find_corners(np.zeros((50, 50)), Chessboard(), refine="subpix", ghost=(1.0, 1.0, 0.05))
    with pytest.raises(ValueError, match=r"ghost must be 'auto', None or \(dx, dy, r\) .* got 'on'"):
        calibrate_rig([], default_rig(), ghost="on")


def test_calibration_skips_the_ghost_on_boards_too_small_to_show_one():
    """Small boards (few corners inside) give no estimate rather than an error; a known ghost is
    taken as is."""
    from lipgen.recon.calibrate import _mirror_ghost
    from lipgen.rig.target import Chessboard

    board = Chessboard(4, 3, 5.0)  # 2 corners inside each: 12 in all
    mirror = [(k, np.zeros((12, 2)), np.zeros((40, 40, 3), np.uint8)) for k in range(6)]
    assert _mirror_ghost(mirror, [board] * 6, "auto", 4) is None
    assert _mirror_ghost(mirror, [board] * 6, None, 4) is None
    known = _mirror_ghost(mirror, [board] * 6, (-7.0, 0.5, 0.05), 4)
    assert known["used"] and known["shift_px"] == [-7.0, 0.5] and known["strength"] == 0.05
