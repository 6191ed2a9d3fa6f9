"""The blurred X-junction fit of chessboard corners (lipgen.recon.cornerfit), against ground truth.

Synthetic boards are drawn with exact pixel-area coverage (16x16 supersampling) at known
sub-pixel corner positions, skewed and turned, blurred and noisy; the fit must find the corners
within a few hundredths of a pixel, and better than OpenCV's ``cornerSubPix`` on the same images.
"""

import numpy as np
import pytest

from lipgen.recon.cornerfit import fit_corners

cv2 = pytest.importorskip("cv2")


def _board(rng, rows=4, cols=5, blur=1.2, noise=2.0, size=(110, 130), ss=16):
    """(H, W) float image of a skewed board in [0.1, 0.9], and its (rows * cols, 2) true corners."""
    sq, ang, skew = rng.uniform(11, 17), rng.uniform(-0.4, 0.4), rng.uniform(-0.2, 0.2)
    origin = rng.uniform(28, 34, 2)
    A = sq * np.array([[np.cos(ang), -np.sin(ang + skew)], [np.sin(ang), np.cos(ang + skew)]])
    H, W = size
    ys, xs = np.mgrid[0:H * ss, 0:W * ss]
    P = np.stack([(xs + 0.5) / ss - 0.5, (ys + 0.5) / ss - 0.5], -1) - origin  # pixel (0, 0) at its centre
    q = P @ np.linalg.inv(A).T
    black = (np.floor(q[..., 0]) + np.floor(q[..., 1])) % 2 == 0
    img = 0.1 + 0.8 * black.reshape(H, ss, W, ss).mean((1, 3))
    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    img = img + rng.normal(0, noise / 255, img.shape)
    j, i = np.mgrid[0:rows, 0:cols]
    return img, origin + np.column_stack([i.ravel(), j.ravel()]) @ A.T, sq


@pytest.mark.parametrize("blur", [0.0, 1.2, 2.5])
def test_fit_recovers_known_corners_better_than_cornersubpix(blur):
    rng = np.random.default_rng(7)
    err_fit, err_cv = [], []
    for _ in range(3):
        img, truth, sq = _board(rng, blur=blur)
        start = truth + rng.uniform(-0.6, 0.6, truth.shape)
        g8 = np.clip(np.round(img * 255), 0, 255).astype(np.uint8)
        half = int(np.clip(sq / 2 - 1, 2, 10))  # find_corners' window
        sp = cv2.cornerSubPix(g8, start.reshape(-1, 1, 2).astype(np.float32), (half, half), (-1, -1),
                              (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)).reshape(-1, 2)
        fit, ok = fit_corners(img, sp.astype(float), (4, 5))
        assert ok.all()
        err_fit.append(fit - truth)
        err_cv.append(sp - truth)
    rms_fit = np.sqrt((np.vstack(err_fit) ** 2).sum(1).mean())
    rms_cv = np.sqrt((np.vstack(err_cv) ** 2).sum(1).mean())
    assert rms_fit < 0.05, rms_fit
    assert np.abs(np.vstack(err_fit).mean(0)).max() < 0.01  # no bias
    assert rms_fit < 0.7 * rms_cv, (rms_fit, rms_cv)


def test_fit_is_unbiased_under_a_tone_curve():
    """The half-turn symmetry: a gamma curve on the blurred image moves no corner."""
    rng = np.random.default_rng(3)
    img, truth, _ = _board(rng, blur=1.5, noise=0.0)
    start = truth + rng.uniform(-0.5, 0.5, truth.shape)
    a, _ = fit_corners(img, start, (4, 5))
    b, _ = fit_corners(img ** (1 / 2.2), start, (4, 5))
    assert np.sqrt(((a - truth) ** 2).sum(1).mean()) < 0.03
    assert np.sqrt(((b - truth) ** 2).sum(1).mean()) < 0.03


def test_fit_keeps_the_start_where_there_is_no_corner():
    start = np.array([[20.0, 20.0], [35.0, 20.0], [50.0, 20.0], [20.0, 35.0], [35.0, 35.0], [50.0, 35.0],
                      [20.0, 50.0], [35.0, 50.0], [50.0, 50.0]])
    flat = np.random.default_rng(0).normal(0.5, 0.01, (70, 70))
    out, ok = fit_corners(flat, start, (3, 3))
    assert np.array_equal(out[~ok], start[~ok])
    assert np.linalg.norm(out - start, axis=1).max() <= 1.5


def test_fit_bad_inputs():
    with pytest.raises(ValueError, match=r"gray must be an \(H, W\) image, got shape \(5, 5, 3\)"):
        fit_corners(np.zeros((5, 5, 3)), np.zeros((9, 2)), (3, 3))
    with pytest.raises(ValueError, match=r"corners must be \(9, 2\) for a 3x3 grid, got shape \(8, 2\)"):
        fit_corners(np.zeros((50, 50)), np.zeros((8, 2)), (3, 3))


def test_find_corners_names_an_unknown_refiner():
    from lipgen.recon.chessboard import find_corners
    from lipgen.rig.target import Chessboard

    with pytest.raises(ValueError, match="refine must be one of .*'saddle'"):
        find_corners(np.zeros((50, 50)), Chessboard(), refine="saddle")
