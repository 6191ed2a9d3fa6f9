"""Pinhole cameras in the OpenCV convention, and ray-midpoint triangulation.

Conventions (DESIGN.md): millimetres; ``x_cam = R @ X + t`` with camera x right, y down, z
forward; pixel (0, 0) is the centre of the top-left pixel, so an image of width W covers
u in [-0.5, W - 0.5]; optional lens distortion as in OpenCV: radial ``(k1, k2[, k3])`` or
radial and tangential ``(k1, k2, p1, p2[, k3])`` (OpenCV's ``distCoeffs`` order).

The camera-mirror rig built from these cameras is :class:`lipgen.rig.camera.MirrorRig`;
``lipgen.rig.camera`` re-exports everything here.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lipgen._validate import as_float_array

__all__ = [
    "PinholeCamera",
    "look_at_rotation",
    "triangulate_rays",
    "triangulate",
]

_NEWTON_STEPS = 30


def _readonly(a) -> np.ndarray:
    a = np.array(a, dtype=np.float64, copy=True)
    a.setflags(write=False)
    return a


def look_at_rotation(eye, target, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """(3, 3) world-to-camera rotation of a camera at ``eye`` looking at ``target``.

    ``up`` (world) appears upward in the image (camera -y). Raises ``ValueError`` when the
    view direction is parallel to ``up`` or ``eye == target``.
    """
    eye = as_float_array(eye, "eye", (3,))
    target = as_float_array(target, "target", (3,))
    up = as_float_array(up, "up", (3,))
    z = target - eye
    if np.linalg.norm(z) == 0:
        raise ValueError(f"eye and target coincide at {eye.tolist()}; a camera needs a view direction")
    z = z / np.linalg.norm(z)
    x = np.cross(z, up)  # camera right = forward x up (with y down)
    if np.linalg.norm(x) < 1e-9 * max(np.linalg.norm(up), 1.0):
        raise ValueError(f"view direction {z.tolist()} is parallel to up {up.tolist()}; choose another up")
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z])


@dataclass(frozen=True, eq=False)
class PinholeCamera:
    """A pinhole camera with optional radial and tangential distortion, OpenCV convention.

    Parameters
    ----------
    K : (3, 3) float
        Intrinsics ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` in pixels (no skew: OpenCV's model
        has none).
    R : (3, 3) float
        World-to-camera rotation, proper (det +1).
    t : (3,) float
        World-to-camera translation in mm: ``x_cam = R @ X + t``.
    width, height : int
        Image size in pixels.
    dist : (2,), (3,), (4,) or (5,) float, optional
        Radial ``(k1, k2[, k3])`` or OpenCV's ``(k1, k2, p1, p2[, k3])``; ``None`` for none.
        Stored as the five OpenCV coefficients ``(k1, k2, p1, p2, k3)``.
    name : str
        A label for messages and files.
    """

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    width: int
    height: int
    dist: np.ndarray | None = None
    name: str = "camera"
    _r_max: float = field(init=False, repr=False, default=np.inf)

    def __post_init__(self) -> None:
        K = as_float_array(self.K, f"{self.name}.K", (3, 3))
        if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
            raise ValueError(f"{self.name}.K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got {K.tolist()}")
        if K[0, 1] != 0:
            raise ValueError(f"{self.name}.K has skew K[0, 1] = {K[0, 1]}; OpenCV's camera model has none")
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ValueError(f"{self.name}: focal lengths must be positive, got fx={K[0, 0]}, fy={K[1, 1]}")
        R = as_float_array(self.R, f"{self.name}.R", (3, 3))
        err = float(np.abs(R @ R.T - np.eye(3)).max())
        if err > 1e-9:
            raise ValueError(f"{self.name}.R is not a rotation: |R R^T - I| = {err:.3g}")
        if np.linalg.det(R) < 0:
            raise ValueError(f"{self.name}.R has determinant -1 (a mirrored camera); reflect the image "
                             "instead, as MirrorRig does for its virtual camera")
        t = as_float_array(self.t, f"{self.name}.t", (3,))
        for key in ("width", "height"):
            val = getattr(self, key)
            if isinstance(val, bool) or int(val) != val or int(val) < 1:
                raise ValueError(f"{self.name}.{key} must be a positive whole number of pixels, got {val!r}")
            object.__setattr__(self, key, int(val))
        dist = None
        if self.dist is not None and len(np.atleast_1d(self.dist)) and np.any(np.asarray(self.dist) != 0):
            dist = as_float_array(self.dist, f"{self.name}.dist", (None,))
            if len(dist) not in (2, 3, 4, 5):
                raise ValueError(f"{self.name}.dist must be (k1, k2[, k3]) or (k1, k2, p1, p2[, k3]), got "
                                 f"shape {dist.shape}")
            if len(dist) <= 3:
                dist = np.r_[dist[:2], 0.0, 0.0, dist[2:3]]
            dist = _readonly(np.pad(dist, (0, 5 - len(dist))))
        object.__setattr__(self, "K", _readonly(K))
        object.__setattr__(self, "R", _readonly(R))
        object.__setattr__(self, "t", _readonly(t))
        object.__setattr__(self, "dist", dist)
        object.__setattr__(self, "_r_max", self._monotone_radius())

    # ---- construction --------------------------------------------------------------------
    @classmethod
    def look_at(cls, eye, target, width: int, height: int, focal: float, up=(0.0, 1.0, 0.0),
                dist=None, name: str = "camera") -> PinholeCamera:
        """A centred camera (principal point ``((W-1)/2, (H-1)/2)``) at ``eye`` looking at ``target``."""
        R = look_at_rotation(eye, target, up)
        K = np.array([[focal, 0, (width - 1) / 2], [0, focal, (height - 1) / 2], [0, 0, 1.0]])
        return cls(K, R, -R @ np.asarray(eye, float), width, height, dist, name)

    def cropped(self, x0: int, y0: int, width: int, height: int, name: str | None = None) -> PinholeCamera:
        """The camera of the sub-image ``image[y0:y0+height, x0:x0+width]`` (principal point shifted)."""
        if not (0 <= x0 and 0 <= y0 and x0 + width <= self.width and y0 + height <= self.height):
            raise ValueError(f"crop ({x0}, {y0}, {width}, {height}) is outside the "
                             f"{self.width}x{self.height} image of {self.name}")
        K = self.K.copy()
        K[0, 2] -= x0
        K[1, 2] -= y0
        return PinholeCamera(K, self.R, self.t, width, height, self.dist, name or self.name)

    def scaled(self, width: int, height: int) -> PinholeCamera:
        """The same camera at another image size of the same aspect (pixel-centre convention)."""
        s = width / self.width
        if abs(height / self.height - s) > 1e-9:
            raise ValueError(f"size {width}x{height} does not keep the aspect of {self.width}x{self.height}")
        K = self.K.copy()
        K[:2, :2] *= s
        K[:2, 2] = (K[:2, 2] + 0.5) * s - 0.5
        return PinholeCamera(K, self.R, self.t, width, height, self.dist, self.name)

    # ---- geometry ------------------------------------------------------------------------
    @property
    def center(self) -> np.ndarray:
        """(3,) centre of projection in world coordinates, mm."""
        return -self.R.T @ self.t

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return self.width, self.height

    def to_camera(self, X) -> np.ndarray:
        """(..., 3) world points in camera coordinates."""
        X = as_float_array(X, "X")
        if X.shape[-1:] != (3,):
            raise ValueError(f"points must have shape (..., 3), got {X.shape}")
        return X @ self.R.T + self.t

    @property
    def tangential(self) -> bool:
        """The lens has tangential (decentring) distortion p1, p2."""
        return self.dist is not None and bool(self.dist[2] or self.dist[3])

    def distort(self, xy: np.ndarray) -> np.ndarray:
        """Apply the lens distortion (OpenCV's model) to normalised image coordinates (..., 2)."""
        if self.dist is None:
            return xy
        k1, k2, p1, p2, k3 = self.dist
        r2 = np.sum(xy * xy, axis=-1, keepdims=True)
        out = xy * (1 + r2 * (k1 + r2 * (k2 + r2 * k3)))
        if self.tangential:
            x, y = xy[..., 0], xy[..., 1]
            out = out + np.stack([2 * p1 * x * y + p2 * (r2[..., 0] + 2 * x * x),
                                  p1 * (r2[..., 0] + 2 * y * y) + 2 * p2 * x * y], axis=-1)
        return out

    def undistort(self, xy_d: np.ndarray) -> np.ndarray:
        """Invert :meth:`distort`: Newton on the radius, then (with tangential terms) 2-D Newton
        steps on the full model, to machine precision."""
        if self.dist is None:
            return xy_d
        xy = self._undistort_radial(xy_d)
        if not self.tangential:
            return xy
        k1, k2, p1, p2, k3 = self.dist
        for _ in range(_NEWTON_STEPS // 3):
            x, y = xy[..., 0], xy[..., 1]
            r2 = x * x + y * y
            rad = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
            g = 2 * (k1 + r2 * (2 * k2 + r2 * 3 * k3))
            res = self.distort(xy) - xy_d
            a = rad + g * x * x + 2 * p1 * y + 6 * p2 * x
            d = rad + g * y * y + 6 * p1 * y + 2 * p2 * x
            b = g * x * y + 2 * p1 * x + 2 * p2 * y  # the Jacobian is symmetric
            det = a * d - b * b
            xy = xy - np.stack([(d * res[..., 0] - b * res[..., 1]) / det,
                                (a * res[..., 1] - b * res[..., 0]) / det], axis=-1)
        return xy

    def _undistort_radial(self, xy_d: np.ndarray) -> np.ndarray:
        k1, k2, _, _, k3 = self.dist
        rd = np.linalg.norm(xy_d, axis=-1, keepdims=True)
        r = rd.copy()
        for _ in range(_NEWTON_STEPS):
            r2 = r * r
            h = r * (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) - rd
            dh = 1 + r2 * (3 * k1 + r2 * (5 * k2 + r2 * 7 * k3))
            r = r - h / dh
        scale = np.divide(r, rd, out=np.ones_like(rd), where=rd > 0)
        return xy_d * scale

    def project(self, X, return_depth: bool = False):
        """Project world points to pixels.

        Parameters
        ----------
        X : (..., 3) float
            World points, mm.
        return_depth : bool
            Also return the depth (camera z, mm).

        Returns
        -------
        uv : (..., 2) float
            Pixel coordinates; NaN for points at or behind the camera (depth <= 0).
        depth : (...,) float
            Only with ``return_depth``.
        """
        Xc = self.to_camera(X)
        z = Xc[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = Xc[..., :2] / z[..., None]
        xy = np.where((z > 0)[..., None], xy, np.nan)
        uv = self.distort(xy) * np.diag(self.K)[:2] + self.K[:2, 2]
        return (uv, z) if return_depth else uv

    def inside(self, uv, margin: float = 0.0) -> np.ndarray:
        """(...,) bool: pixel positions inside the image, at least ``margin`` px from its edge."""
        uv = np.asarray(uv, float)
        lo = -0.5 + margin
        with np.errstate(invalid="ignore"):
            return ((uv[..., 0] >= lo) & (uv[..., 0] <= self.width - 0.5 - margin)
                    & (uv[..., 1] >= lo) & (uv[..., 1] <= self.height - 0.5 - margin))

    def in_view(self, X, margin: float = 0.0) -> np.ndarray:
        """(...,) bool: points in front of the camera that project inside the image (no occlusion test)."""
        Xc = self.to_camera(X)
        z = Xc[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.linalg.norm(Xc[..., :2], axis=-1) / z
        # beyond the monotone range of the distortion, a point may wrap back into the image
        return (z > 0) & (r <= self._r_max) & self.inside(self.project(X), margin)

    def normalized(self, uv) -> np.ndarray:
        """(..., 2) undistorted normalised coordinates ``(x/z, y/z)`` of pixels ``uv``."""
        uv = as_float_array(uv, "uv")
        if uv.shape[-1:] != (2,):
            raise ValueError(f"pixel coordinates must have shape (..., 2), got {uv.shape}")
        return self.undistort((uv - self.K[:2, 2]) / np.diag(self.K)[:2])

    def rays(self, uv) -> tuple[np.ndarray, np.ndarray]:
        """Back-project pixels to world rays.

        Returns
        -------
        origins : (..., 3) float
            The camera centre, repeated.
        directions : (..., 3) float
            Unit directions in the world frame.
        """
        xy = self.normalized(uv)
        d = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1) @ self.R
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        return np.broadcast_to(self.center, d.shape).copy(), d

    def opencv_dist(self) -> np.ndarray:
        """(5,) OpenCV ``distCoeffs`` ``(k1, k2, p1, p2, k3)``."""
        return np.zeros(5) if self.dist is None else self.dist.copy()

    def mirrored_dist(self) -> np.ndarray | None:
        """The distortion seen through a left-right flipped image (x -> -x): p2 changes sign."""
        return None if self.dist is None else self.dist * np.array([1.0, 1.0, 1.0, -1.0, 1.0])

    # ---- files ---------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """Plain JSON-able description (OpenCV convention, mm)."""
        return {"convention": "opencv", "units": "mm", "name": self.name,
                "width": self.width, "height": self.height, "K": self.K.tolist(),
                "R": self.R.tolist(), "t": self.t.tolist(),
                "dist": None if self.dist is None else self.dist.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> PinholeCamera:
        """Inverse of :meth:`to_dict`; refuses other conventions."""
        if d.get("convention") != "opencv":
            raise ValueError(f"camera convention {d.get('convention')!r} is not supported; expected 'opencv'")
        return cls(np.array(d["K"]), np.array(d["R"]), np.array(d["t"]), d["width"], d["height"],
                   None if d.get("dist") is None else np.array(d["dist"]), d.get("name", "camera"))

    def _monotone_radius(self) -> float:
        """Largest undistorted radius up to which the distortion is one-to-one.

        Raises ``ValueError`` if the image corners lie beyond it (the distortion folds the image).
        """
        if self.dist is None:
            return np.inf
        k1, k2, _, _, k3 = self.dist
        corners = np.array([[-0.5, -0.5], [self.width - 0.5, -0.5], [-0.5, self.height - 0.5],
                            [self.width - 0.5, self.height - 0.5]])
        rd_corner = np.linalg.norm((corners - self.K[:2, 2]) / np.diag(self.K)[:2], axis=1).max()
        r = np.linspace(0.0, 10.0 * rd_corner + 1.0, 200001)
        r2 = r * r
        dh = 1 + r2 * (3 * k1 + r2 * (5 * k2 + r2 * 7 * k3))
        bad = np.flatnonzero(dh <= 0)
        r_max = r[bad[0] - 1] if len(bad) else np.inf
        h_max = r_max * (1 + r_max**2 * (k1 + r_max**2 * (k2 + r_max**2 * k3))) if len(bad) else np.inf
        if h_max < rd_corner:
            raise ValueError(
                f"{self.name}: radial distortion {self.dist.tolist()} folds the image (not one-to-one "
                f"beyond normalised radius {h_max:.3g}, but the image corners reach {rd_corner:.3g}); "
                "use smaller coefficients")
        return float(r_max)


def triangulate_rays(o1, d1, o2, d2) -> tuple[np.ndarray, np.ndarray]:
    """Closest points between pairs of rays; their midpoint and the gap between them.

    Parameters
    ----------
    o1, o2 : (..., 3) float
        Ray origins (camera centres), mm.
    d1, d2 : (..., 3) float
        Ray directions (any length, not zero).

    Returns
    -------
    points : (..., 3) float
        Midpoints of the shortest segments joining the rays (thesis §3, Fig 3-5); NaN for
        parallel rays.
    gap : (...,) float
        Lengths of those segments, mm: zero for rays that meet (NaN for parallel rays).
    """
    o1, d1, o2, d2 = (np.asarray(a, float) for a in (o1, d1, o2, d2))
    d1 = d1 / np.linalg.norm(d1, axis=-1, keepdims=True)
    d2 = d2 / np.linalg.norm(d2, axis=-1, keepdims=True)
    w = o1 - o2
    b = np.sum(d1 * d2, axis=-1)
    d = np.sum(d1 * w, axis=-1)
    e = np.sum(d2 * w, axis=-1)
    denom = 1.0 - b * b
    parallel = denom <= 1e-14
    denom = np.where(parallel, np.nan, denom)
    s = (b * e - d) / denom
    u = (e - b * d) / denom
    p1 = o1 + s[..., None] * d1
    p2 = o2 + u[..., None] * d2
    return 0.5 * (p1 + p2), np.linalg.norm(p1 - p2, axis=-1)


def triangulate(cam1: PinholeCamera, uv1, cam2: PinholeCamera, uv2) -> tuple[np.ndarray, np.ndarray]:
    """Ray-midpoint triangulation of matching pixels ``uv1 (..., 2)`` in ``cam1`` and ``uv2`` in ``cam2``.

    Returns ``(points (..., 3), gap (...,))`` as :func:`triangulate_rays`.
    """
    uv1 = as_float_array(uv1, "uv1")
    uv2 = as_float_array(uv2, "uv2")
    if uv1.shape != uv2.shape:
        raise ValueError(f"uv1 and uv2 must have the same shape, got {uv1.shape} and {uv2.shape}")
    o1, dir1 = cam1.rays(uv1)
    o2, dir2 = cam2.rays(uv2)
    return triangulate_rays(o1, dir1, o2, dir2)
