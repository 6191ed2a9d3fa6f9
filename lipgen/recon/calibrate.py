"""Calibrating the camera-mirror rig from images of a known target (thesis §3).

The thesis calibrated its real and virtual cameras with Azarbayejani and Pentland's method.
Here a planar chessboard is filmed in several poses. Each raw frame is split into its (virtual,
real) views and the board's inner corners are found (OpenCV) and fitted to sub-pixel
(:func:`lipgen.recon.cornerfit.fit_corners`). The rig is then
fitted as what it physically is, ONE camera and ONE mirror: the virtual view is the real
camera looking at the reflected board, so both views share the intrinsics (focal lengths,
principal point, radial k1 k2 and tangential p1 p2), and the mirror plane adds 3 parameters.
OpenCV's single-camera calibration of the direct view and a PnP of the mirrored board give the
starting point; a bundle adjustment over all corners of both views (scipy least squares) refines intrinsics,
mirror and board poses together. That is better conditioned than calibrating each view alone:
a small board near the face constrains the principal point poorly, and the second view pins it.

The world frame of the result is the board's frame in the ``reference`` image (origin at
inner corner 0, x along the corner rows, y along the columns, z = x × y), so a board placed at
a known pose there gives cameras in that known frame.

Tangential distortion (p1, p2) of a real lens's size (about 1e-3) is nearly unidentifiable from
boards small enough to be seen whole in both views: apart from a camera turn and a principal-point
shift, what p2 adds across one board is a curvature of a few hundredths of a pixel, which each
board's pose absorbs (hard preset's lens, rendered frames, seeds 0-2: p1, p2 9-75 % off). Lens
frames fix that, as in real lens calibration: a dense board (:data:`lipgen.rig.target.LENS_BOARD`)
fills the direct or the mirror view (the principal point is at the split, so each view covers
half the sensor); such a frame, seen in one view only, constrains the shared intrinsics and its
own pose in the same joint fit. With 30 lens frames beside 10 both-view frames, p1 and p2 come
within about 10 % (k1, k2 within 2 %). ``board`` may therefore be one board per image.

The mirror view holds a faint ghost of itself (the glass's front surface), which moves every
corner of a mirror board by about the same amount (``hard``: about 0.09 px), enough to pull p1
or p2 past 10 %. :func:`calibrate_rig` estimates the ghost's shift and strength from all the mirror
boards together (:func:`lipgen.recon.ghost.estimate_ghost`) and, where the images show one, fits
the mirror corners again with it modelled. On ``hard`` validation seeds 0-2 and 6-8 this takes each
mirror board's mean corner error from 0.12-0.13 px to 0.01-0.02 px, p1 and p2 from up to 12 % off
to within 4.4 %, and the rig's 3-D error from 0.09-0.14 mm to 0.016-0.031 mm; ``easy`` frames
show no ghost and calibrate as before. It costs CPU: calibrating 40 ``hard`` frames took 52 s
instead of 35 s.

OpenCV (``opencv-python-headless``) is imported when a calibration runs.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from lipgen._optional import require
from lipgen._validate import as_float_array
from lipgen.errors import DatasetError
from lipgen.recon.bundle import _bundle_adjust
from lipgen.recon.chessboard import find_corners, linear_gray
from lipgen.recon.cornerfit import fit_corners, ghost_params
from lipgen.recon.ghost import estimate_ghost
from lipgen.rig.camera import VIEWS, MirrorRig
from lipgen.rig.pinhole import PinholeCamera
from lipgen.rig.target import Chessboard

__all__ = ["Chessboard", "RigCalibration", "find_corners", "calibrate_rig", "calibrate_from_corners",
           "compare_to_truth"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class RigCalibration:
    """A calibrated camera-mirror rig and how well it fits its images.

    Attributes
    ----------
    rig : MirrorRig
        The fitted camera and mirror, in the frame of the board in the reference image.
    rms : dict
        Reprojection RMS in pixels after the joint fit: ``"real"``, ``"virtual"`` and ``"all"``;
        ``"real_alone"`` is OpenCV's single-camera fit of the direct view, for comparison.
    n_images : dict
        Calibration images with the whole board found, per view, and ``"both"``.
    reference : int
        The calibration image whose board frame is the world frame.
    per_image : tuple of dict
        Per calibration image: ``{"image": k, "virtual": rms px or None, "real": ...}`` (None: the
        board was not found whole in that view, or the view was dropped as an outlier).
    dropped : tuple of dict
        Views of images left out as outliers: ``{"image": k, "view": name, "rms_px": ...}``.
    ghost : dict or None
        The mirror view's ghost as estimated (:meth:`lipgen.recon.ghost.Ghost.to_dict`, shift in
        the mirror view's split image, plus ``"used"``: whether the corners were fitted with it);
        None when not estimated.
    """

    rig: MirrorRig
    rms: dict
    n_images: dict
    reference: int
    per_image: tuple = ()
    dropped: tuple = ()
    ghost: dict | None = None

    @property
    def views(self) -> tuple[PinholeCamera, PinholeCamera]:
        """(virtual_view, real_view), in :data:`lipgen.rig.camera.VIEWS` order."""
        return self.rig.views

    def triangulate(self, uv_real, uv_virtual) -> tuple[np.ndarray, np.ndarray]:
        """Ray-midpoint triangulation of split-view pixels: ``(points (..., 3), gap (...,))``."""
        return self.rig.triangulate(uv_real, uv_virtual)

    def in_frame(self, rotation, translation) -> RigCalibration:
        """The same rig with the world redefined: old world point p is ``rotation @ p + translation``."""
        A = as_float_array(rotation, "rotation", (3, 3))
        b = as_float_array(translation, "translation", (3,))
        c, r = self.rig.camera, self.rig
        cam = PinholeCamera(c.K, c.R @ A.T, c.t - c.R @ A.T @ b, c.width, c.height, c.dist, c.name)
        n = A @ r.mirror_normal
        moved = MirrorRig(cam, n, r.mirror_offset + n @ b, r.mirror_side, r.split)
        return RigCalibration(moved, dict(self.rms), dict(self.n_images), self.reference, self.per_image,
                              self.dropped, self.ghost)

    def to_dict(self) -> dict:
        """A JSON-ready dict of the calibration (cameras, errors, settings)."""
        return {"rig": self.rig.to_dict(), "rms_px": self.rms, "n_images": self.n_images,
                "reference": self.reference, "per_image_rms_px": list(self.per_image),
                "dropped": list(self.dropped), "ghost": self.ghost}

    @classmethod
    def from_dict(cls, d: dict) -> RigCalibration:
        """The calibration written by :meth:`to_dict`."""
        return cls(MirrorRig.from_dict(d["rig"]), dict(d["rms_px"]), dict(d["n_images"]), int(d["reference"]),
                   tuple(d.get("per_image_rms_px", ())), tuple(d.get("dropped", ())), d.get("ghost"))


_TANGENTIAL_GAIN = 1.05  # keep p1, p2 if they cut the RMS by 5 % (noise alone: ~0.1 %) ...
_TANGENTIAL_CHI2 = 50.0  # ... or cut the squared residuals by 50 noise variances (noise alone: chi2(2))


def calibrate_rig(raw_frames: Sequence, layout: MirrorRig, board: Chessboard = Chessboard(),
                  reference: int = 0, distortion: bool = True, min_images: int = 4,
                  outlier_factor: float = 4.0, outlier_floor_px: float = 1.0, ghost="auto") -> RigCalibration:
    """Calibrate the camera and the mirror from raw frames of a chessboard.

    Parameters
    ----------
    raw_frames : sequence of (H, W[, 3]) arrays
        Raw camera-mirror frames of the board in different poses.
    layout : MirrorRig
        Used only for the image layout (size, split column, mirror side), never for its cameras.
    board : Chessboard or sequence of Chessboard
        The board, or one per frame (lens frames may show a larger one).
    reference : int
        The frame whose board pose defines the world frame; the board must be whole in its
        direct view.
    distortion : bool or str
        The lens model: ``"radial"`` (k1, k2), ``"full"`` (k1, k2 and tangential p1, p2),
        ``False`` (none), or ``True``: radial, and the tangential terms too when they lower the
        reprojection RMS by more than 5 %, or the sum of squared residuals by more than 50 times
        the per-axis noise variance (for noise alone that drop is chi-square with 2 degrees of
        freedom; measured 0.7-2.2 on ideal and mild lenses, far above 50 with lens frames).
    min_images : int
        Fewest frames with the whole board in the direct view, and in the mirror.
    outlier_factor, outlier_floor_px : float
        After the joint fit, an image's view whose reprojection RMS exceeds both
        ``outlier_factor`` times the median over all image views and ``outlier_floor_px`` is
        dropped (a blurred or mis-detected board), with a warning, and the rig is fitted again
        without it (once). Per-image errors are in :attr:`RigCalibration.per_image`.
    ghost : "auto", None or (3,) float
        The mirror view's ghost: ``"auto"`` estimates it from the mirror boards (at least
        ``min_images`` of them) and models it in their corners when the images show one
        (:attr:`lipgen.recon.ghost.Ghost.shown`); None: not modelled; or a known
        ``(dx, dy, r)`` in the mirror view's split image (see
        :func:`lipgen.recon.cornerfit.fit_corners`).

    Returns
    -------
    RigCalibration

    Raises
    ------
    DatasetError
        Too few usable frames, or no board in the reference frame's direct view.
    """
    require("cv2", "chessboard calibration")
    if not (ghost is None or (isinstance(ghost, str) and ghost == "auto")):  # checked before the work
        ghost_params(ghost, "ghost must be 'auto', None or (dx, dy, r) with 0 <= r < 1")
    raw_frames = list(raw_frames)
    boards = _boards(board, len(raw_frames))
    obs: list[dict[str, np.ndarray]] = []
    mirror = []  # (image, split-view corners, mirror view) of every mirror board found
    for k, (raw, b) in enumerate(zip(raw_frames, boards, strict=True)):
        virt, real = layout.split_views(np.asarray(raw))
        per = {}
        for view, img in (("virtual", virt), ("real", real)):
            uv = find_corners(img, b)
            if uv is not None:
                per[view] = layout.to_raw(view, uv)
                if view == "virtual":
                    mirror.append((k, uv, virt))
        obs.append(per)
    found = _mirror_ghost(mirror, boards, ghost, min_images, grays := [])
    if found is not None and found["used"]:
        params = np.r_[found["shift_px"], found["strength"]]
        for i, (k, uv, virt) in enumerate(mirror):
            shape = (boards[k].inner_rows, boards[k].inner_cols)
            uv = fit_corners(grays[i] if grays else linear_gray(virt), uv, shape, ghost=params)[0]
            obs[k]["virtual"] = layout.to_raw("virtual", uv)
    cal = calibrate_from_corners(obs, layout, board, reference, distortion, min_images, outlier_factor,
                                 outlier_floor_px)
    return replace(cal, ghost=found)


_GHOST_MIN_CORNERS = 20  # corners one step inside their boards, fewest to estimate a ghost from


def _mirror_ghost(mirror, boards, ghost, min_images, grays=None) -> dict | None:
    """The ghost of :func:`calibrate_rig` as a dict (with ``"used"``), or None when not estimated.
    The mirror boards' linear grey images, when made for the estimate, are appended to ``grays``."""
    if ghost is None:
        return None
    if not isinstance(ghost, str):
        g = np.asarray(ghost, float)
        return {"shift_px": g[:2].tolist(), "strength": float(g[2]), "snr": None, "corners": None,
                "used": True}
    shapes = [(boards[k].inner_rows, boards[k].inner_cols) for k, _, _ in mirror]
    interior = sum(max(r - 2, 0) * max(c - 2, 0) for r, c in shapes)
    if len(mirror) < min_images or interior < _GHOST_MIN_CORNERS:
        log.info("calibration: too few mirror boards (%d) or inner corners (%d) to estimate a ghost",
                 len(mirror), interior)
        return None
    images = [linear_gray(virt) for _, _, virt in mirror]
    if grays is not None:
        grays.extend(images)
    try:
        est = estimate_ghost(images, [uv for _, uv, _ in mirror], shapes)
    except np.linalg.LinAlgError as e:  # degenerate boards: no ghost can be told
        log.info("calibration: the mirror ghost could not be estimated (%s)", e)
        return None
    used = est.shown
    log.info("calibration: mirror ghost %.2f %.2f px, strength %.4f (%.0f standard errors): %s", *est.shift,
             est.strength, est.snr, "modelled" if used else "not modelled")
    return est.to_dict() | {"used": bool(used)}


def calibrate_from_corners(obs: Sequence[dict], layout: MirrorRig, board: Chessboard = Chessboard(),
                           reference: int = 0, distortion: bool | str = True, min_images: int = 4,
                           outlier_factor: float = 4.0, outlier_floor_px: float = 1.0) -> RigCalibration:
    """Calibrate from board corners already found: ``obs[k]`` maps a view name to the
    ``(n_corners, 2)`` raw-frame pixels of the whole board in image k (views where it was not
    found are left out). Parameters and result as :func:`calibrate_rig`."""
    if distortion not in (True, False, "radial", "full"):
        raise ValueError(f"distortion must be True, False, 'radial' or 'full', got {distortion!r}")
    obs = [dict(per) for per in obs]  # outlier views are dropped from a copy, not the caller's list
    board = _boards(board, len(obs))
    cal, sq = _fit_rig(obs, layout, board, reference, distortion, min_images)
    keys = [(k, view) for k, per in enumerate(obs) for view in per]
    per_view = np.sqrt([q.mean() for q in sq])
    limit = max(outlier_factor * float(np.median(per_view)), outlier_floor_px)
    bad = [(k, view, float(r)) for (k, view), r in zip(keys, per_view, strict=True) if r > limit]
    if bad:
        for k, view, r in bad:
            log.warning("calibration image %d: the %s view's board reprojects %.2f px RMS (> %.2f px, %g x "
                        "the median): left out", k, view, r, limit, outlier_factor)
            del obs[k][view]
        cal, sq = _fit_rig(obs, layout, board, reference, distortion, min_images)
        keys = [(k, view) for k, per in enumerate(obs) for view in per]
        per_view = np.sqrt([q.mean() for q in sq])
    table = {k: {"image": k, "virtual": None, "real": None} for k in range(len(obs))}
    for (k, view), r in zip(keys, per_view, strict=True):
        table[k][view] = float(r)
    return RigCalibration(cal.rig, cal.rms, cal.n_images, reference, tuple(table.values()),
                          tuple({"image": k, "view": v, "rms_px": r} for k, v, r in bad))


def _boards(board, n: int) -> list[Chessboard]:
    """One board per calibration image: ``board`` itself, or its ``n`` entries."""
    if isinstance(board, Chessboard):
        return [board] * n
    boards = list(board)
    if len(boards) != n or not all(isinstance(b, Chessboard) for b in boards):
        raise ValueError(f"board must be a Chessboard or one per calibration image ({n}), got "
                         f"{len(boards)} items of types {sorted({type(b).__name__ for b in boards})}")
    return boards


def _fit_rig(obs, layout, boards, reference, distortion, min_images) -> tuple[RigCalibration, list]:
    """The joint fit of :func:`calibrate_rig` on the found corners ``obs`` (per image: view -> (n, 2))
    of ``boards`` (one per image); returns the calibration and the squared residuals (one (n,)
    array per image view, in ``obs`` order)."""
    cv2 = require("cv2", "chessboard calibration")
    W, H = layout.camera.width, layout.camera.height
    objs = [b.object_points() for b in boards]
    board = boards[reference] if 0 <= reference < len(boards) else boards[0]
    counts = {v: sum(v in per for per in obs) for v in VIEWS} | {"both": sum(len(p) == 2 for p in obs)}
    log.info("calibration: board found in %s of %d frames", counts, len(obs))
    if min(counts.values()) < min_images:
        raise DatasetError(
            f"the calibration board ({board.inner_cols}x{board.inner_rows} inner corners, {board.square} mm "
            f"squares) was found whole in {counts} of {len(obs)} frames (virtual, real, both); need "
            f"{min_images} each. Check the calibration frames and the board described in the manifest")
    if not 0 <= reference < len(obs) or "real" not in obs[reference]:
        raise DatasetError(f"calibration frame {reference} does not show the whole board in the direct view; "
                           "choose another reference frame")
    flags = cv2.CALIB_FIX_K3 | (0 if distortion == "full" else cv2.CALIB_ZERO_TANGENT_DIST)
    if distortion is False:
        flags |= cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2
    real_k = [k for k, per in enumerate(obs) if "real" in per]
    rms_alone, K, dist, rvecs, tvecs = cv2.calibrateCamera(
        [objs[k].astype(np.float32) for k in real_k], [obs[k]["real"].astype(np.float32) for k in real_k],
        (W, H), None, None, flags=flags)
    dist = dist.ravel()
    poses = {k: (cv2.Rodrigues(r)[0], t.ravel()) for k, r, t in zip(real_k, rvecs, tvecs, strict=True)}
    # The mirrored board is a proper object with its y axis flipped: its PnP pose gives the
    # reflection S = R_m D R_b^T, hence the mirror plane (S = I - 2 n n^T; t_m = S t_b + 2 d n).
    D = np.diag([1.0, -1.0, 1.0])
    S_sum, d_terms = np.zeros((3, 3)), []
    for k in (k for k in real_k if "virtual" in obs[k]):
        _, rv, tv = cv2.solvePnP((objs[k] @ D).astype(np.float32), obs[k]["virtual"].astype(np.float32), K,
                                 dist)
        S_k = cv2.Rodrigues(rv)[0] @ D @ poses[k][0].T
        S_sum += S_k
        d_terms.append((tv.ravel() - S_k @ poses[k][1], S_k))
    w, vecs = np.linalg.eigh(0.5 * (S_sum + S_sum.T) / max(len(d_terms), 1))
    n0 = vecs[:, 0]
    d0 = float(np.mean([n0 @ dt / 2.0 for dt, _ in d_terms]))
    for k in (k for k in range(len(obs)) if k not in poses and obs[k]):  # seen only in the mirror
        _, rv, tv = cv2.solvePnP((objs[k] @ D).astype(np.float32), obs[k]["virtual"].astype(np.float32), K,
                                 dist)
        S0 = np.eye(3) - 2 * np.outer(n0, n0)
        poses[k] = (S0 @ cv2.Rodrigues(rv)[0] @ D, S0 @ (tv.ravel() - 2 * d0 * n0))
    model = {True: "radial", False: "none"}.get(distortion, distortion)
    fit = _bundle_adjust(objs, obs, K, dist, poses, n0, d0, model)
    if distortion is True:
        K1 = np.array([[fit[0][0], 0.0, fit[1][0]], [0.0, fit[0][1], fit[1][1]], [0.0, 0.0, 1.0]])
        full = _bundle_adjust(objs, obs, K1, fit[2], dict(fit[5]), fit[3], fit[4], "full")
        if _rms(fit[6]) > _TANGENTIAL_GAIN * _rms(full[6]) or _drop(fit[6], full[6]) > _TANGENTIAL_CHI2:
            fit, model = full, "full"
    f, c, kk, n, d, poses, res, which = fit
    K_fit = np.array([[f[0], 0.0, c[0]], [0.0, f[1], c[1]], [0.0, 0.0, 1.0]])
    R_ref, t_ref = poses[reference]
    kk = np.r_[kk, 0.0] if model != "none" else None  # OpenCV order (k1, k2, p1, p2, k3)
    cam = PinholeCamera(K_fit, _orthonormal(R_ref), t_ref, W, H, kk, "real")
    rig = MirrorRig(cam, R_ref.T @ n, d - n @ t_ref, layout.mirror_side, layout.split)
    sq = [(r ** 2).sum(-1) for r in res]
    rms = {v: _rms([r for r, w in zip(res, which, strict=True) if w == v]) for v in VIEWS} | {
        "all": _rms(res), "real_alone": float(rms_alone)}
    return RigCalibration(rig, rms, counts, reference), sq


def _drop(res_radial: list, res_full: list) -> float:
    """How much p1, p2 lower the sum of squared residuals, in units of the per-axis noise variance
    left by the full fit (for noise alone about chi-square with 2 degrees of freedom)."""
    sq_r, sq_f = (np.concatenate([(r ** 2).sum(-1) for r in res]) for res in (res_radial, res_full))
    return float((sq_r.sum() - sq_f.sum()) / (sq_f.sum() / (2 * len(sq_f))))


def _rms(res: list) -> float:
    """RMS pixel error of residual arrays ``(n_i, 2)``."""
    return float(np.sqrt(np.concatenate([(r ** 2).sum(-1) for r in res]).mean()))


def _orthonormal(R: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(np.asarray(R, float))
    return U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt


def _angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    c = (np.trace(Ra.T @ Rb) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def compare_to_truth(cal: RigCalibration, true_views: Sequence[PinholeCamera]) -> dict:
    """How far the calibration is from the true view cameras (both in the same world frame).

    Parameters
    ----------
    cal : RigCalibration
        Already expressed in the true world frame (see :meth:`RigCalibration.in_frame`).
    true_views : (virtual, real) PinholeCamera

    Returns
    -------
    dict
        Per view: focal error (px, fx and fy), principal-point error (px), rotation error
        (degrees), centre error (mm); and the error of the real-to-virtual relative pose, which
        does not depend on the world frame (rotation degrees, baseline mm).
    """
    out = {}
    for name, est, true in zip(VIEWS, cal.views, true_views, strict=True):
        out[name] = {
            "focal_px": (np.diag(est.K)[:2] - np.diag(true.K)[:2]).tolist(),
            "principal_point_px": float(np.linalg.norm(est.K[:2, 2] - true.K[:2, 2])),
            "rotation_deg": _angle(est.R, true.R),
            "center_mm": float(np.linalg.norm(est.center - true.center)),
        }
    (ev, er), (tv, tr) = cal.views, tuple(true_views)
    out["relative"] = {
        "rotation_deg": _angle(ev.R @ er.R.T, tv.R @ tr.R.T),
        "baseline_mm": float(np.linalg.norm(ev.center - er.center) - np.linalg.norm(tv.center - tr.center)),
    }
    return out
