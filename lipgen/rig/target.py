"""The calibration target: a chessboard filmed through the rig in several known poses.

The board is :class:`Chessboard` (corner 0 has a black outer diagonal square;
board frame: origin at corner 0, x along a row of corners, y along a column, z = x × y) with a
white margin two squares wide. As in OpenCV's calibration, the printed face is the board's -z
side: a camera looking at it sees x to the right and y downward, z pointing away. Poses put it
near the mouth, tilted, wholly inside both views and
facing both cameras, so that :func:`lipgen.recon.calibrate.calibrate_rig` can recover the rig from
the images alone. A pose is stored as ``world X = A p + b`` for board points ``p``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from lipgen.rig.camera import MirrorRig
from lipgen.rig.scene import Light, Material, MeshItem, Scene

__all__ = ["Chessboard", "board_item", "board_scene", "board_poses", "board_outline"]

_MARGIN = 2  # white squares around the pattern (a quiet zone for corner detectors)
_BLACK = Material("board_black", (0.03, 0.03, 0.03), 0.9, label=4)
_WHITE = Material("board_white", (0.92, 0.92, 0.90), 0.9, label=5)


@dataclass(frozen=True)
class Chessboard:
    """A planar chessboard target.

    Attributes
    ----------
    inner_cols, inner_rows : int
        Inner corners along x and y of the board; one even and one odd, so that the board has
        no 180-degree symmetry and corners are numbered the same way in every view. Corner 0 is
        the one whose outer diagonal square is black: the board frame has its origin there, x
        along the rows of corners, y along the columns, z = x × y.
    square : float
        Side of a square, mm.
    """

    inner_cols: int = 9
    inner_rows: int = 6
    square: float = 4.0

    def __post_init__(self) -> None:
        if min(self.inner_cols, self.inner_rows) < 3:
            raise ValueError(f"a chessboard needs at least 3x3 inner corners, got "
                             f"{self.inner_cols}x{self.inner_rows}")
        if (self.inner_cols + self.inner_rows) % 2 == 0:
            raise ValueError(f"a {self.inner_cols}x{self.inner_rows} board is symmetric under a half "
                             "turn; make one of the corner counts even and the other odd")
        if not self.square > 0:
            raise ValueError(f"square must be a positive size in mm, got {self.square!r}")

    def object_points(self) -> np.ndarray:
        """(inner_cols * inner_rows, 3) corner positions in the board frame, mm, row by row."""
        j, i = np.mgrid[0:self.inner_rows, 0:self.inner_cols]
        return np.column_stack([i.ravel(), j.ravel(), np.zeros(i.size)]) * self.square


def board_outline(board: Chessboard) -> np.ndarray:
    """(4, 3) corners of the whole board including its white margin, board frame, mm."""
    s = board.square
    x0, x1 = -(1 + _MARGIN) * s, (board.inner_cols + _MARGIN) * s
    y0, y1 = -(1 + _MARGIN) * s, (board.inner_rows + _MARGIN) * s
    return np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]])


def board_item(board: Chessboard, pose: np.ndarray, name: str = "board") -> MeshItem:
    """The board as a mesh in the world: ``pose`` (4, 4) maps board points to world points."""
    s = board.square
    xs = np.arange(-1 - _MARGIN, board.inner_cols + _MARGIN + 1) * s
    ys = np.arange(-1 - _MARGIN, board.inner_rows + _MARGIN + 1) * s
    gx, gy = np.meshgrid(xs, ys)
    V = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    nx = len(xs)
    cy, cx = np.mgrid[0:len(ys) - 1, 0:nx - 1]
    a = (cy * nx + cx).ravel()
    quads = np.stack([a, a + 1, a + nx + 1, a + nx], 1)
    F = np.vstack([quads[:, [0, 2, 1]], quads[:, [0, 3, 2]]])  # counter-clockwise seen from -z
    # square (i, j) spans [i s, (i+1) s] x [j s, (j+1) s]
    i, j = cx.ravel() - 1 - _MARGIN, cy.ravel() - 1 - _MARGIN
    pattern = (i >= -1) & (i <= board.inner_cols - 1) & (j >= -1) & (j <= board.inner_rows - 1)
    black = pattern & ((i + j) % 2 == 0)  # square (-1, -1), outside corner 0, is black
    mat = np.tile(np.where(black, 0, 1), 2)
    A, b = pose[:3, :3], pose[:3, 3]
    N = np.tile(-A[:, 2], (len(V), 1))
    return MeshItem(name, V @ A.T + b, F, (_BLACK, _WHITE), mat, N)


def board_scene(board: Chessboard, pose: np.ndarray, background=(0.40, 0.45, 0.50)) -> Scene:
    """A scene of the board alone, evenly lit from the cameras' side."""
    lights = (Light("directional", (1.0, 1.0, 1.0), 2.5, direction=(-0.1, -0.2, -1.0)),
              Light("directional", (1.0, 1.0, 1.0), 1.0, direction=(0.4, 0.0, -1.0)))
    return Scene((board_item(board, pose),), lights, (0.3, 0.3, 0.3), tuple(background),
                 {4: "board:black", 5: "board:white"})


def board_poses(rig: MirrorRig, board: Chessboard, n: int, seed=0, center=(0.0, 5.0, 0.0),
                max_tilt_deg: float = 25.0, max_shift_mm: float = 20.0, margin_px: float = 4.0) -> np.ndarray:
    """``n`` board poses (4, 4), board to world, each wholly seen directly and in the mirror.

    Tilts of up to ``max_tilt_deg`` about x and y (and a third of it about z) and shifts of up
    to ``max_shift_mm`` around ``center``, drawn with ``seed``; poses that leave a view, or
    show either camera the board's back, are drawn again.

    Raises
    ------
    ValueError
        If the rig cannot see the board whole in both views at all.
    """
    rng = np.random.default_rng(seed)
    facing = np.diag([1.0, -1.0, -1.0])  # printed face (-z) toward the cameras, x right, y down
    outline = board_outline(board)
    mid = outline.mean(axis=0)
    corners = np.vstack([outline, board.object_points()])
    out = []
    for _ in range(200 * n):
        if len(out) == n:
            break
        tilt = np.radians(rng.uniform(-1, 1, 3) * max_tilt_deg * np.array([1.0, 1.0, 1 / 3]))
        A = Rotation.from_euler("xyz", tilt).as_matrix() @ facing
        shift = rng.uniform(-1, 1, 3) * max_shift_mm * np.array([1.0, 1.0, 0.5])
        b = np.asarray(center, float) + shift - A @ mid
        X = corners @ A.T + b
        front = all((cam.center - X[0]) @ A[:, 2] < 0 for cam in rig.views)
        if not front or not all(cam.in_view(X, margin_px).all() for cam in rig.views):
            continue
        if (rig.mirror_distance(X) <= 0).any():
            continue
        P = np.eye(4)
        P[:3, :3], P[:3, 3] = A, b
        out.append(P)
    if len(out) < n:
        raise ValueError(f"found only {len(out)} of {n} board poses that both views see whole; the "
                         f"{board.inner_cols}x{board.inner_rows} board of {board.square} mm squares may be "
                         "too big for this rig, or the tilt/shift ranges too wide")
    return np.stack(out)
