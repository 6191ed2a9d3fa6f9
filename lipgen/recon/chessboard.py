"""Finding a chessboard's inner corners in one view, numbered without ambiguity.

OpenCV (``opencv-python-headless``) is imported when corners are searched for.
"""

from __future__ import annotations

import numpy as np

from lipgen._optional import require
from lipgen.recon.cornerfit import fit_corners
from lipgen.recon.dots import as_gray
from lipgen.rig.scene import srgb_to_linear
from lipgen.rig.target import Chessboard

__all__ = ["find_corners", "REFINERS", "linear_gray"]

REFINERS = ("fit", "subpix")
"""Ways :func:`find_corners` refines the corners: ``"fit"`` (the blurred X-junction model,
:func:`lipgen.recon.cornerfit.fit_corners`, started from ``"subpix"``), or ``"subpix"`` (OpenCV's
``cornerSubPix`` alone)."""


def linear_gray(image) -> np.ndarray:
    """The grey image in linear light: :func:`lipgen.recon.dots.as_gray` through the sRGB decoding curve.

    Parameters
    ----------
    image : (H, W[, 3]) array
        An sRGB-encoded image (uint8, uint16, or float in [0, 1]).

    Returns
    -------
    (H, W) float
    """
    return srgb_to_linear(as_gray(image))


def find_corners(image, board: Chessboard, refine: str = "fit", ghost=None) -> np.ndarray | None:
    """Sub-pixel inner corners of ``board`` in ``image``, or ``None`` if it is not found whole.

    OpenCV's detector (the classic one, then the sector-based one) finds the grid; the corners
    are refined with ``cornerSubPix`` in a window of about half a square, then (``refine="fit"``)
    by fitting a blurred X-junction to every pixel of a disc reaching 0.7 of the way to the
    neighbouring corners (:func:`lipgen.recon.cornerfit.fit_corners`); and the numbering is
    made unambiguous by the board's colours: corner 0 is the one whose outer diagonal square
    is black (see :class:`Chessboard`).

    On rendered ``hard`` calibration frames (validation seed 0, 10 frames, against the truth
    projections) the fit takes the corners' RMS error from 0.125 to 0.044 px in the direct view,
    and their scatter about each board's mean from 0.18 to 0.05 px in the mirror view; on the
    same frames without defocus, noise, Bayer, JPEG and ghost, from 0.11-0.13 to 0.04 px
    (``cornerSubPix``'s own error on the rendered edges, which noise, Bayer and JPEG barely add
    to). What is left in the mirror view is the glass's front-surface ghost (4 %, 7.3 px to the
    side in ``hard``): it shifts every corner of a board by about 0.09 px, with either method
    (towards the ghost with ``cornerSubPix``, away from it with the fit). Given the ghost
    (``ghost``, e.g. from :func:`lipgen.recon.ghost.estimate_ghost`), the fit models it, in
    linear light (:func:`linear_gray`): the boards' mean errors fall to 0.01-0.02 px (``hard``
    validation seeds 0-2, 6-8), which :func:`lipgen.recon.calibrate.calibrate_rig` does itself.

    Parameters
    ----------
    image : (H, W[, 3]) array
        One view (not a raw frame).
    board : Chessboard
    refine : str
        One of :data:`REFINERS`.
    ghost : (3,) float or None
        The view's ghost ``(dx, dy, r)`` (see :func:`lipgen.recon.cornerfit.fit_corners`), for
        ``refine="fit"``; None: no ghost.

    Returns
    -------
    (inner_cols * inner_rows, 2) float or None
        Pixel positions (column, row), in :meth:`Chessboard.object_points` order.
    """
    if refine not in REFINERS:
        raise ValueError(f"refine must be one of {REFINERS}, got {refine!r}")
    if ghost is not None and refine != "fit":
        raise ValueError(f"a ghost is modelled by refine='fit' only, got refine={refine!r} with "
                         f"ghost={ghost!r}")
    cv2 = require("cv2", "chessboard calibration")
    gray_f = as_gray(image)
    gray = np.clip(np.round(gray_f * 255), 0, 255).astype(np.uint8)
    size = (board.inner_cols, board.inner_rows)
    found, corners = cv2.findChessboardCorners(
        gray, size, flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not found:
        found, corners = cv2.findChessboardCornersSB(
            gray, size, flags=cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_EXHAUSTIVE)
    if not found:
        return None
    pts = corners.reshape(-1, 2).astype(np.float64)
    grid = pts.reshape(board.inner_rows, board.inner_cols, 2)
    spacing = min(np.linalg.norm(np.diff(grid, axis=0), axis=2).min(),
                  np.linalg.norm(np.diff(grid, axis=1), axis=2).min())
    half = int(np.clip(spacing / 2 - 1, 2, 10))
    refined = cv2.cornerSubPix(gray, pts.reshape(-1, 1, 2).astype(np.float32), (half, half), (-1, -1),
                               (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4))
    pts = refined.reshape(-1, 2).astype(np.float64)
    if refine == "fit":
        pts = fit_corners(gray_f, pts, (board.inner_rows, board.inner_cols))[0]
        if ghost is not None:  # from the plain fit's corners, within a tenth of a pixel
            pts = fit_corners(linear_gray(image), pts, (board.inner_rows, board.inner_cols), ghost=ghost)[0]
    return pts if _origin_is_black(gray, pts, board) else pts[::-1].copy()


def _origin_is_black(gray: np.ndarray, pts: np.ndarray, board: Chessboard) -> bool:
    """Whether the square diagonally outside corner 0 is darker than the one outside the last.

    The board has no half-turn symmetry, so exactly one of the two outer-corner squares is
    black; their centres are found through the homography of the detected grid.
    """
    cv2 = require("cv2", "chessboard calibration")
    obj = board.object_points()[:, :2] / board.square
    H, _ = cv2.findHomography(obj.astype(np.float32), pts.astype(np.float32))
    probes = np.array([[-0.5, -0.5], [board.inner_cols - 0.5, board.inner_rows - 0.5]])
    uvw = np.column_stack([probes, np.ones(2)]) @ H.T
    uv = uvw[:, :2] / uvw[:, 2:]
    h, w = gray.shape
    ij = np.clip(np.round(uv).astype(int), 0, [w - 1, h - 1])
    first, last = gray[ij[:, 1], ij[:, 0]].astype(float)
    return first <= last
