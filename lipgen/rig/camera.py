"""The camera-mirror rig (thesis ch. 3, Figs 3-2..3-5) and its pinhole cameras.

One real camera films the face directly in one half of its image and, in the other half, the
face's reflection in a planar mirror beside the face. The mirror half is equivalent to a
second, *virtual* camera: the real camera reflected in the mirror plane. A reflection is an
improper transform (det -1), so the virtual camera is made proper by flipping its image x
axis; its image is then the horizontally flipped raw frame, which is why the mirror half of
the raw frame looks mirrored and :meth:`MirrorRig.split_views` flips it back (Fig 3-4).

Each half is described by its own :class:`~lipgen.rig.pinhole.PinholeCamera` (``real_view``,
``virtual_view``), whose pixels are those of the split, corrected views. Views are ordered as
in :data:`VIEWS`: virtual (left in the thesis), then real.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lipgen._validate import as_float_array
from lipgen.rig.pinhole import PinholeCamera, look_at_rotation, triangulate, triangulate_rays

__all__ = [
    "PinholeCamera",
    "MirrorRig",
    "VIEWS",
    "default_rig",
    "rig_from_eyes",
    "look_at_rotation",
    "triangulate",
    "triangulate_rays",
]

VIEWS: tuple[str, str] = ("virtual", "real")
"""Order of the two views in every per-view array (as thesis Fig 3-4: virtual left, real right)."""

_FLIP_X = np.diag([-1.0, 1.0, 1.0])


@dataclass(frozen=True, eq=False)
class MirrorRig:
    """One real camera and a planar mirror beside the face.

    Parameters
    ----------
    camera : PinholeCamera
        The real camera; its image is the whole raw frame.
    mirror_normal : (3,) float
        Normal of the mirror plane ``n . X = mirror_offset`` (world frame, any length). It is
        oriented toward the camera on construction (the camera is on the reflective side).
    mirror_offset : float
        Plane offset in mm (for the normal as given).
    mirror_side : {"left", "right"}
        The half of the raw frame filled by the mirror (the thesis has it on the left).
    split : int, optional
        First column of the right half; defaults to ``width // 2``. The mirror's edge is seen
        along this column.

    Attributes
    ----------
    virtual : PinholeCamera
        The real camera reflected in the mirror, made proper; its image is the raw frame
        flipped left-right (``virtual_flip = "horizontal"``).
    real_view, virtual_view : PinholeCamera
        Cameras of the two split, corrected views (see :meth:`split_views`).
    """

    camera: PinholeCamera
    mirror_normal: np.ndarray
    mirror_offset: float
    mirror_side: str = "left"
    split: int | None = None
    virtual: PinholeCamera = field(init=False, repr=False)
    real_view: PinholeCamera = field(init=False, repr=False)
    virtual_view: PinholeCamera = field(init=False, repr=False)
    virtual_flip: str = field(init=False, default="horizontal")

    def __post_init__(self) -> None:
        cam = self.camera
        if not isinstance(cam, PinholeCamera):
            raise TypeError(f"camera must be a PinholeCamera, got {type(cam).__name__}")
        n = as_float_array(self.mirror_normal, "mirror_normal", (3,))
        length = float(np.linalg.norm(n))
        if length == 0:
            raise ValueError("mirror_normal is the zero vector; give the mirror plane's normal")
        d = float(as_float_array(self.mirror_offset, "mirror_offset", ())) / length
        n = n / length
        side = float(n @ cam.center - d)
        if abs(side) < 1e-9:
            raise ValueError(f"the camera centre {cam.center.tolist()} lies on the mirror plane; "
                             "it would see the mirror edge-on")
        if side < 0:
            n, d = -n, -d
        if self.mirror_side not in ("left", "right"):
            raise ValueError(f"mirror_side must be 'left' or 'right', got {self.mirror_side!r}")
        W, H = cam.width, cam.height
        split = W // 2 if self.split is None else self.split
        if isinstance(split, bool) or int(split) != split or not 1 <= int(split) <= W - 1:
            raise ValueError(f"split must be a column in [1, {W - 1}], got {split!r}")
        split = int(split)
        n.setflags(write=False)
        object.__setattr__(self, "mirror_normal", n)
        object.__setattr__(self, "mirror_offset", d)
        object.__setattr__(self, "split", split)
        # Virtual camera: x_c = R (S X + 2 d n) + t is improper; flip image x to make it proper.
        S = np.eye(3) - 2.0 * np.outer(n, n)
        K = cam.K.copy()
        K[0, 2] = W - 1 - K[0, 2]
        virtual = PinholeCamera(K, _FLIP_X @ cam.R @ S, _FLIP_X @ (cam.R @ (2 * d * n) + cam.t),
                                W, H, cam.mirrored_dist(), "virtual")
        object.__setattr__(self, "virtual", virtual)
        if self.mirror_side == "left":
            real_x0, virt_x0, real_w, virt_w = split, W - split, W - split, split
        else:
            real_x0, virt_x0, real_w, virt_w = 0, 0, split, W - split
        object.__setattr__(self, "real_view", cam.cropped(real_x0, 0, real_w, H, "real"))
        object.__setattr__(self, "virtual_view", virtual.cropped(virt_x0, 0, virt_w, H, "virtual"))
        mid_col = split / 2 - 0.5 if self.mirror_side == "left" else (split + W - 1) / 2
        o, ray = cam.rays(np.array([mid_col, (H - 1) / 2]))
        if not (ray @ n) < 0:
            raise ValueError(
                f"the mirror half ({self.mirror_side}) of the image does not look at the mirror plane "
                f"(normal {n.round(4).tolist()}, offset {d:.4g} mm): its central ray never meets it. "
                "Aim the camera so that the mirror fills that half")

    # ---- geometry ------------------------------------------------------------------------
    @property
    def views(self) -> tuple[PinholeCamera, PinholeCamera]:
        """The view cameras in :data:`VIEWS` order: (virtual_view, real_view)."""
        return self.virtual_view, self.real_view

    def reflect(self, X) -> np.ndarray:
        """(..., 3) mirror images of world points ``X``."""
        X = as_float_array(X, "X")
        n = self.mirror_normal
        return X - 2.0 * (X @ n - self.mirror_offset)[..., None] * n

    def mirror_distance(self, X) -> np.ndarray:
        """(...,) signed distance of points from the mirror plane, positive on the camera's side."""
        return as_float_array(X, "X") @ self.mirror_normal - self.mirror_offset

    def project(self, X, margin: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Project world points into both views.

        Returns
        -------
        uv : (2, ..., 2) float
            Pixels in the split views, :data:`VIEWS` order (NaN behind a camera).
        depth : (2, ...) float
            Camera depth, mm.
        in_view : (2, ...) bool
            In front of the camera, inside the view, and (for the mirror) on the reflective
            side of the mirror. Occlusion by surfaces is not tested here.
        """
        X = as_float_array(X, "X")
        uv, depth, inside = [], [], []
        for cam in self.views:
            p, z = cam.project(X, return_depth=True)
            uv.append(p)
            depth.append(z)
            inside.append(cam.in_view(X, margin))
        inside[0] = inside[0] & (self.mirror_distance(X) > 0)
        return np.stack(uv), np.stack(depth), np.stack(inside)

    def triangulate(self, uv_real, uv_virtual) -> tuple[np.ndarray, np.ndarray]:
        """Ray-midpoint triangulation (thesis §3) of matching split-view pixels.

        Parameters
        ----------
        uv_real, uv_virtual : (..., 2) float
            Pixels in the real and the (corrected) virtual view.

        Returns
        -------
        points : (..., 3) float
            World points, mm.
        gap : (...,) float
            Distance between the two rays at their closest approach, mm.
        """
        return triangulate(self.real_view, uv_real, self.virtual_view, uv_virtual)

    # ---- images --------------------------------------------------------------------------
    def halves(self) -> tuple[slice, slice]:
        """Raw-frame column slices of the (mirror, direct) halves."""
        s = self.split
        return (slice(0, s), slice(s, None)) if self.mirror_side == "left" else (slice(s, None), slice(0, s))

    def split_views(self, raw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Cut a raw frame ``(H, W[, C])`` into the corrected (virtual, real) views (thesis Fig 3-4).

        The mirror half is flipped left-right; the views are copies.
        """
        raw = np.asarray(raw)
        W, H = self.camera.width, self.camera.height
        if raw.ndim not in (2, 3) or raw.shape[:2] != (H, W):
            raise ValueError(f"raw frame must have shape ({H}, {W}) or ({H}, {W}, C) for this rig, "
                             f"got {raw.shape}")
        mirror, direct = self.halves()
        return raw[:, mirror][:, ::-1].copy(), raw[:, direct].copy()

    def compose(self, virtual: np.ndarray, real: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`split_views`: the raw frame from the two corrected view images."""
        virtual, real = np.asarray(virtual), np.asarray(real)
        for img, cam in ((virtual, self.virtual_view), (real, self.real_view)):
            if img.shape[:2] != (cam.height, cam.width):
                raise ValueError(f"{cam.name} view image must be {cam.height}x{cam.width}, got {img.shape}")
        if virtual.shape[2:] != real.shape[2:] or virtual.dtype != real.dtype:
            raise ValueError(f"view images differ in channels or dtype: {virtual.shape} {virtual.dtype} "
                             f"vs {real.shape} {real.dtype}")
        raw = np.empty((self.camera.height, self.camera.width) + real.shape[2:], real.dtype)
        mirror, direct = self.halves()
        raw[:, mirror] = virtual[:, ::-1]
        raw[:, direct] = real
        return raw

    def to_raw(self, view: str, uv) -> np.ndarray:
        """(..., 2) raw-frame pixels of split-view pixels ``uv`` of ``view`` ("virtual" or "real")."""
        uv = np.array(as_float_array(uv, "uv", finite=False), copy=True)
        if view == "real":
            uv[..., 0] += 0 if self.mirror_side == "right" else self.split
        elif view == "virtual":
            x0 = self.camera.width - self.split if self.mirror_side == "left" else 0
            uv[..., 0] = self.camera.width - 1 - (uv[..., 0] + x0)
        else:
            raise ValueError(f"view must be one of {VIEWS}, got {view!r}")
        return uv

    # ---- checks --------------------------------------------------------------------------
    def check_sees(self, X, margin: float = 0.0, what: str = "face") -> None:
        """Raise ``ValueError`` unless every point is seen directly and in the mirror.

        Parameters
        ----------
        X : (n, 3) float
            Points that must be visible (e.g. the face over its motion range), mm.
        margin : float
            Required distance from the view edges, px.
        what : str
            What the points are, for the message.
        """
        X = as_float_array(X, "X", (None, 3))
        W = self.camera.width
        direct = self.real_view.in_view(X, margin)
        if not direct.all():
            uv_raw, z = self.camera.project(X, return_depth=True)
            seen = self.camera.in_view(X)
            where = _describe(uv_raw, z)
            if not seen.any():
                raise ValueError(f"the camera sees nothing of the {what}: {where}; the {W}x"
                                 f"{self.camera.height} image shows none of it. Aim the camera at it.")
            raise ValueError(
                f"{int((~direct).sum())} of {len(X)} {what} point(s) are not inside the direct "
                f"({'right' if self.mirror_side == 'left' else 'left'}) half with a {margin} px margin: "
                f"{where}; the direct half is columns {self._cols('real')}")
        behind = self.mirror_distance(X) <= 0
        if behind.any():
            raise ValueError(
                f"the mirror plane (normal {self.mirror_normal.round(4).tolist()}, offset "
                f"{self.mirror_offset:.4g} mm) does not show the {what}: {int(behind.sum())} of {len(X)} "
                "point(s) lie behind it, on the far side from the camera")
        mirrored = self.virtual_view.in_view(X, margin)
        if not mirrored.all():
            uv_raw = self.camera.project(self.reflect(X[~mirrored]), return_depth=True)
            raise ValueError(
                f"the mirror plane (normal {self.mirror_normal.round(4).tolist()}, offset "
                f"{self.mirror_offset:.4g} mm) does not show the {what}: {int((~mirrored).sum())} of "
                f"{len(X)} reflected point(s) fall outside the mirror ({self.mirror_side}) half with a "
                f"{margin} px margin: {_describe(*uv_raw)}; the mirror half is columns "
                f"{self._cols('virtual')}")

    def _cols(self, view: str) -> str:
        mirror, direct = self.halves()
        s = mirror if view == "virtual" else direct
        return f"[{s.start}, {self.camera.width if s.stop is None else s.stop})"

    # ---- files ---------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """Plain JSON-able description: the real camera, the mirror plane, derived view cameras."""
        return {"convention": "opencv", "units": "mm", "camera": self.camera.to_dict(),
                "mirror": {"normal": self.mirror_normal.tolist(), "offset": self.mirror_offset,
                           "equation": "normal . X = offset, normal toward the camera"},
                "mirror_side": self.mirror_side, "split": self.split, "virtual_flip": self.virtual_flip,
                "virtual": self.virtual.to_dict(), "views": {v: c.to_dict() for v, c in zip(
                    VIEWS, self.views, strict=True)}}

    @classmethod
    def from_dict(cls, d: dict) -> MirrorRig:
        """Inverse of :meth:`to_dict` (the derived cameras are recomputed)."""
        return cls(PinholeCamera.from_dict(d["camera"]), np.array(d["mirror"]["normal"]),
                   float(d["mirror"]["offset"]), d.get("mirror_side", "left"), d.get("split"))


def _describe(uv: np.ndarray, z: np.ndarray) -> str:
    front = z > 0
    if not front.any():
        return "all of it is behind the camera"
    u, v = uv[front, 0], uv[front, 1]
    behind = f"{int((~front).sum())} behind the camera, " if (~front).any() else ""
    return f"{behind}raw pixels u in [{u.min():.0f}, {u.max():.0f}], v in [{v.min():.0f}, {v.max():.0f}]"


def rig_from_eyes(real_eye, virtual_eye, target, width: int, height: int, focal: float | None = None,
                  up=(0.0, 1.0, 0.0), mirror_side: str = "left", dist=None) -> MirrorRig:
    """A rig whose real and virtual cameras sit at ``real_eye`` and ``virtual_eye``.

    The mirror is the plane bisecting the two eyes. The real camera aims so that ``target``
    (world, mm) is seen at the centre of the direct half and its reflection at the centre of the
    mirror half; ``focal`` (px) defaults to the value that centres them exactly.
    """
    real_eye = as_float_array(real_eye, "real_eye", (3,))
    virtual_eye = as_float_array(virtual_eye, "virtual_eye", (3,))
    target = as_float_array(target, "target", (3,))
    n = real_eye - virtual_eye
    if np.linalg.norm(n) == 0:
        raise ValueError("real_eye and virtual_eye coincide; the mirror needs two distinct eyes")
    n = n / np.linalg.norm(n)
    d = float(n @ (real_eye + virtual_eye) / 2)
    reflected = target - 2 * (target @ n - d) * n
    a = (target - real_eye) / np.linalg.norm(target - real_eye)
    b = (reflected - real_eye) / np.linalg.norm(reflected - real_eye)
    R = look_at_rotation(real_eye, real_eye + a + b, up)
    x, _, z = R @ (target - real_eye)
    if (x > 0) != (mirror_side == "left"):
        raise ValueError(f"with these eyes the mirror appears on the {'left' if x > 0 else 'right'}, "
                         f"not on the {mirror_side}; swap the eyes or mirror_side")
    f = (width / 4) / abs(x / z) if focal is None else float(focal)
    K = np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1.0]])
    cam = PinholeCamera(K, R, -R @ real_eye, width, height, dist, "real")
    return MirrorRig(cam, n, d, mirror_side)


def default_rig(width: int = 640, height: int = 480) -> MirrorRig:
    """The default rig: face directly in the right half, the mirror in the left half (thesis Fig 3-3).

    The real camera looks at the mouth from 22 degrees to the subject's left, 320 mm away; the
    virtual camera sees it from 22 degrees to the subject's right, 400 mm away, so the mirror
    stands beside the face on the subject's right, about 100 mm from the mouth centre. At
    640x480 the focal length is about 582 px (1.8 px/mm on the lips directly, 1.45 px/mm in the
    mirror). Both views keep the lips and the nose inside with a margin over head rotations of
    +-10 degrees and translations of +-10 mm. Other 4:3 sizes scale the intrinsics.
    """
    if width * 3 != height * 4:
        raise ValueError(f"the default rig is 4:3; got {width}x{height}. Build another with rig_from_eyes()")
    target = np.array([0.0, 5.0, 0.0])
    yaw = np.radians(22.0)
    real_eye = target + 320.0 * np.array([np.sin(yaw), 0.0, np.cos(yaw)])
    virtual_eye = target + 400.0 * np.array([-np.sin(yaw), 0.0, np.cos(yaw)])
    rig = rig_from_eyes(real_eye, virtual_eye, target, 640, 480)
    if (width, height) == (640, 480):
        return rig
    return MirrorRig(rig.camera.scaled(width, height), rig.mirror_normal, rig.mirror_offset, "left")
