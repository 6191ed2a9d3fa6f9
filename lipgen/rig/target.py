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

__all__ = ["Chessboard", "board_item", "board_scene", "board_poses", "board_outline", "LENS_BOARD",
           "lens_poses", "lens_view", "calibration_targets"]

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


LENS_BOARD = Chessboard(17, 24, 6.0)
"""The lens frames' board: 17 x 24 inner corners of 6 mm (132 x 174 mm with its margin, about
A5), portrait, dense, and large enough to fill half the frame near the face. Its 408 corners per
frame matter: at a real lens's size, what p1 and p2 add across one board that its pose cannot
absorb is a few hundredths of a pixel (see :mod:`lipgen.recon.calibrate`)."""


def lens_view(i: int) -> str:
    """The view lens frame ``i`` fills: ``"real"`` for even ``i``, ``"virtual"`` (the mirror) for odd."""
    return "real" if i % 2 == 0 else "virtual"


def lens_poses(rig: MirrorRig, board: Chessboard, n: int, seed=0, mirror_extent=(0.0, 0.0),
               max_tilt_deg: float = 40.0, fill=(0.7, 0.95), quiet_squares: float = 0.5,
               margin_px: float = 4.0, min_square: float = 0.02) -> np.ndarray:
    """``n`` lens-frame poses (4, 4), board to world: the board fills one view of the raw frame.

    Real lens calibration films a board that fills the image in varied tilts, so that the lens
    is seen over the whole sensor. Here the principal point is at the split, so each view covers
    half the sensor: lens frame ``i`` fills the view :func:`lens_view` names (the direct view for
    even ``i``, the mirror view for odd ``i``: the board stands where the mirror shows it). The
    other view may see the board in part or not at all. Each pose is tilted up to
    ``max_tilt_deg`` about the view's x and y axes (and a quarter of it about z), placed so that
    the pattern with its quiet border spans about a fraction in ``fill`` of the view's width or
    height (the larger; perspective changes it a little), and
    shifted at random within the view.

    Parameters
    ----------
    rig : MirrorRig
    board : Chessboard
        Usually :data:`LENS_BOARD`.
    n : int
        Poses wanted.
    seed : int or numpy.random.Generator
    mirror_extent : (2,) float
        Half sizes of the mirror, mm (:func:`lipgen.rig.imaging.on_mirror`); zeros: infinite.
    max_tilt_deg : float
    fill : (2,) float
        Range of the pattern's extent over the view's, drawn uniformly.
    quiet_squares : float
        White border around the pattern (in squares) that must be seen as well, for the corner
        detector.
    margin_px : float
        Distance from the view's edges, px.
    min_square : float
        Shortest side of a projected square, as a fraction of the view's height (a strongly
        foreshortened board is not found by the corner detector).

    Returns
    -------
    (n, 4, 4) float

    Raises
    ------
    ValueError
        If no pose fills a view (e.g. a board too large for the rig).
    """
    from lipgen.rig.imaging import on_mirror

    rng = np.random.default_rng(seed)
    s, q = board.square, quiet_squares + 1.0
    edge = np.array([[-q * s, -q * s, 0], [(board.inner_cols - 1 + q) * s, -q * s, 0],
                     [(board.inner_cols - 1 + q) * s, (board.inner_rows - 1 + q) * s, 0],
                     [-q * s, (board.inner_rows - 1 + q) * s, 0]])
    obj = board.object_points()
    pts = np.vstack([edge, obj])
    mid = obj.mean(axis=0)
    whole = np.vstack([board_outline(board), pts])
    out = []
    for _ in range(400 * max(n, 1)):
        if len(out) == n:
            break
        view = lens_view(len(out))
        cam = rig.real_view if view == "real" else rig.virtual_view
        tilt = np.radians(rng.uniform(-1, 1, 3) * max_tilt_deg * np.array([1.0, 1.0, 0.25]))
        A_cam = Rotation.from_euler("xyz", tilt).as_matrix()  # board x, y along the image's, z away
        A = cam.R.T @ A_cam
        uv0 = np.array([cam.width, cam.height]) * rng.uniform(0.3, 0.7, 2)
        ray = cam.R.T @ np.linalg.solve(cam.K, np.r_[uv0, 1.0])
        b1 = cam.center + 300.0 * ray / np.linalg.norm(ray) - A @ mid
        uv = cam.project(pts @ A.T + b1)
        span = np.ptp(uv, axis=0) / np.array([cam.width, cam.height])
        if not np.isfinite(span).all():
            continue
        depth = 300.0 * span.max() / rng.uniform(*fill)
        b = cam.center + depth * ray / np.linalg.norm(ray) - A @ mid
        X = pts @ A.T + b
        if not (cam.center - X[0]) @ A[:, 2] < 0 or not cam.in_view(X, margin_px).all():
            continue
        grid = cam.project(X[len(edge):]).reshape(board.inner_rows, board.inner_cols, 2)
        side = min(np.linalg.norm(np.diff(grid, axis=a), axis=-1).min() for a in (0, 1))
        if side < min_square * cam.height:
            continue
        if (rig.mirror_distance(whole @ A.T + b) <= 0).any():
            continue
        if view == "virtual" and not on_mirror(rig, mirror_extent, X).all():
            continue
        P = np.eye(4)
        P[:3, :3], P[:3, 3] = A, b
        out.append(P)
    if len(out) < n:
        raise ValueError(f"found only {len(out)} of {n} lens-frame poses that fill a view; the "
                         f"{board.inner_cols}x{board.inner_rows} board of {board.square} mm squares may be "
                         "too big for this rig")
    return np.stack(out)


def calibration_targets(rig: MirrorRig, board: Chessboard, n_both: int, n_lens: int = 0, seed=0,
                        mirror_extent=(0.0, 0.0)) -> list[tuple[Chessboard, np.ndarray, str | None]]:
    """The boards of a dataset's calibration frames: ``n_both`` poses of ``board`` seen whole in both
    views (:func:`board_poses`), then ``n_lens`` lens frames of :data:`LENS_BOARD` (:func:`lens_poses`),
    all drawn in turn from one generator (so the first poses do not depend on ``n_lens``).

    Returns
    -------
    list of (Chessboard, (4, 4) pose, view or None)
        Per frame: its board, its pose (board to world) and, for a lens frame, the view it fills.
    """
    rng = np.random.default_rng(seed)
    out = [(board, P, None) for P in board_poses(rig, board, n_both, seed=rng)] if n_both else []
    if n_lens:
        L = lens_poses(rig, LENS_BOARD, n_lens, seed=rng, mirror_extent=mirror_extent)
        out += [(LENS_BOARD, P, lens_view(i)) for i, P in enumerate(L)]
    return out
