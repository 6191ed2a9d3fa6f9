"""Offscreen rendering of the camera-mirror rig with pyrender (the only module importing pyrender).

One raw frame is what the real camera sees (thesis Fig 3-3): the face directly in one half and
its reflection in the mirror in the other, flipped left-right. Each half is rendered from its
own view camera (:attr:`MirrorRig.real_view`, :attr:`MirrorRig.virtual_view`), so the pixels
agree exactly with :meth:`MirrorRig.project`; the mirror half is then flipped into place by
:meth:`MirrorRig.compose` and dimmed by the mirror's reflectance. The two halves together have
as many pixels as one full frame.

OpenGL conventions stay in this module: pyrender's cameras look down -z with y up, and its
principal point is measured from the pixel corner (OpenCV's from the pixel centre, hence +0.5).
Radial distortion, which OpenGL cannot draw, is applied by resampling a wider pinhole render.
"""

from __future__ import annotations

import functools
import hashlib
import os
from dataclasses import dataclass

import numpy as np

from lipgen._optional import require
from lipgen._threads import single_threaded
from lipgen.errors import MissingDependencyError, RenderBackendError
from lipgen.rig import _onepass, _shadowmap
from lipgen.rig.camera import MirrorRig
from lipgen.rig.pinhole import PinholeCamera
from lipgen.rig.scene import MeshItem, Scene, srgb_to_linear

__all__ = ["RigRenderer", "RenderedFrame", "import_pyrender"]

_INSTALL = ("install Mesa's EGL and GL drivers (Debian/Ubuntu: apt install libegl1 libgl1-mesa-dri "
            "libgles2), or set PYOPENGL_PLATFORM=osmesa with libosmesa6 installed")


def import_pyrender():
    """Import pyrender for offscreen EGL rendering (``PYOPENGL_PLATFORM=egl`` unless set).

    Raises
    ------
    MissingDependencyError
        pyrender is not installed.
    RenderBackendError
        pyrender is installed but no OpenGL library could be loaded.
    """
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    try:
        return require("pyrender", "offscreen rendering")
    except MissingDependencyError as exc:
        if isinstance(exc.__cause__, ModuleNotFoundError) and exc.__cause__.name == "pyrender":
            raise
        raise RenderBackendError(f"pyrender could not load OpenGL (PYOPENGL_PLATFORM="
                                 f"{os.environ['PYOPENGL_PLATFORM']}): {exc.__cause__}; {_INSTALL}") from exc


@dataclass(frozen=True, eq=False)
class RenderedFrame:
    """One raw frame of the rig.

    Attributes
    ----------
    image : (H, W, 3) uint8
        The raw frame (sRGB), mirror half flipped as the camera sees it.
    depth : (H, W) float32 or None
        Depth along each half's view camera axis, mm; 0 where nothing was drawn.
    labels : (H, W) uint8 or None
        Label of the surface seen at each pixel (see ``Scene.labels``; 0 is background).
    """

    image: np.ndarray
    depth: np.ndarray | None = None
    labels: np.ndarray | None = None


class _View:
    """A view camera as pyrender draws it, plus the resampling map when it has distortion."""

    def __init__(self, pyrender, cam: PinholeCamera, znear: float, zfar: float) -> None:
        self.cam = cam
        K = cam.K
        x0 = y0 = 0.0
        w, h = cam.width, cam.height
        if cam.dist is not None:
            # where each output pixel comes from in an undistorted render of the same K
            uu, vv = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
            xy = cam.normalized(np.stack([uu, vv], -1))
            src = xy * np.diag(K)[:2] + K[:2, 2]
            lo, hi = np.floor(src.min(axis=(0, 1))) - 2, np.ceil(src.max(axis=(0, 1))) + 2
            x0, y0 = lo
            w, h = int(hi[0] - lo[0]) + 1, int(hi[1] - lo[1]) + 1
            s = src - lo
            self.cv2 = require("cv2", "rendering a camera with lens distortion")
            self.map = s.astype(np.float32)  # bilinear resampling by OpenCV's remap (1/32 px weights)
            self.nearest = np.round(s[..., 1]).astype(np.int64) * w + np.round(s[..., 0]).astype(np.int64)
        self.size = (w, h)
        gl = pyrender.IntrinsicsCamera(K[0, 0], K[1, 1], K[0, 2] - x0 + 0.5, K[1, 2] - y0 + 0.5, znear, zfar)
        pose = np.eye(4)
        pose[:3, :3] = cam.R.T @ np.diag([1.0, -1.0, -1.0])
        pose[:3, 3] = cam.center
        self.node = pyrender.Node(camera=gl, matrix=pose)

    def resample(self, color: np.ndarray, depth: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
        if self.cam.dist is None:
            return color, depth
        color = self.cv2.remap(color, self.map, None, self.cv2.INTER_LINEAR,
                               borderMode=self.cv2.BORDER_REPLICATE)
        return color, None if depth is None else depth.ravel()[self.nearest]


class RigRenderer:
    """Renders :class:`~lipgen.rig.scene.Scene` s through a :class:`~lipgen.rig.camera.MirrorRig`.

    Holds one offscreen OpenGL context (EGL) for its lifetime; make one per process and reuse
    it. Geometry is uploaded again only for items whose arrays changed.

    Parameters
    ----------
    rig : MirrorRig
    mirror_reflectance : float
        Fraction of light the mirror returns (a silvered mirror: about 0.9).
    znear, zfar : float
        Clipping depths, mm.
    shadows : bool
        Directional lights cast shadows (shadow maps).
    one_pass : bool
        Draw both views in one forward pass and read them back once (:mod:`lipgen.rig._onepass`);
        False renders each view on its own (pyrender's way, kept to measure against).
    """

    def __init__(self, rig: MirrorRig, mirror_reflectance: float = 0.9, znear: float = 20.0,
                 zfar: float = 5000.0, shadows: bool = False, one_pass: bool = True) -> None:
        if not isinstance(rig, MirrorRig):
            raise TypeError(f"rig must be a MirrorRig, got {type(rig).__name__}")
        if not 0 < mirror_reflectance <= 1:
            raise ValueError(f"mirror_reflectance must be in (0, 1], got {mirror_reflectance}")
        self.pyrender = pr = import_pyrender()
        self.rig, self.reflectance = rig, float(mirror_reflectance)
        self._flags = pr.RenderFlags.SHADOWS_DIRECTIONAL if shadows else pr.RenderFlags.NONE
        self._views = [_View(pr, cam, znear, zfar) for cam in rig.views]
        w, h = self._views[0].size
        try:
            self._renderer = pr.OffscreenRenderer(w, h)
        except Exception as exc:  # EGL/GL failures surface as many types
            raise RenderBackendError(
                f"no offscreen OpenGL context (PYOPENGL_PLATFORM={os.environ.get('PYOPENGL_PLATFORM')}): "
                f"{type(exc).__name__}: {exc}. To fix: {_INSTALL}") from exc
        self._one_pass = bool(one_pass) and _onepass.install(self._renderer, pr)
        if shadows:  # pyrender's shadow filter in 16 depth reads, not 36: the same pixels
            _shadowmap.install(self._renderer)
        self._scene = _ordered_scene(pr)()
        for v in self._views:
            self._scene.add_node(v.node)
        self._items: dict[str, dict] = {}
        self._textures: dict[int, tuple] = {}  # id(array) -> (array, pyrender Texture): uploaded once
        self._lights: tuple = ()
        self._light_nodes: list = []

    # ---- scene sync -----------------------------------------------------------------------
    def _sync(self, scene: Scene, labels: bool) -> None:
        """Bring the pyrender scene up to date; upload only items whose arrays changed.

        Colour nodes group faces by appearance (few draw calls); label nodes group them by
        label and exist only once labels are asked for, hidden except in the label pass.
        """
        pr = self.pyrender
        self._scene.bg_color = np.append(scene.background, 1.0)  # the clear colour is not gamma-corrected
        self._scene.ambient_light = srgb_to_linear(scene.ambient)
        wanted = {it.name: it for it in scene.items}
        for name in list(self._items):
            if name not in wanted:
                self._drop(self._items.pop(name))
        for name, item in wanted.items():
            key = _fingerprint(item)
            old = self._items.get(name)
            if old is not None and old["key"] == key:
                if labels and old["label"] is None:
                    old["label"] = self._add_label_nodes(item)
                continue
            if old is not None:
                self._drop(old)
            groups = _groups(item, lambda m: (m.color, m.roughness, m.double_sided,
                                              None if m.texture is None else id(m.texture), m.opacity))
            meshes = [_pyrender_mesh(pr, item, faces, mat, self._textures) for faces, mat in groups]
            colour = [self._scene.add(m, name=m.name) for m in meshes]
            self._items[name] = {"key": key, "colour": colour,
                                 "label": self._add_label_nodes(item) if labels else None}
        if scene.lights != self._lights:
            for node in self._light_nodes:
                self._scene.remove_node(node)
            shadows = self._flags != pr.RenderFlags.NONE
            lights = [_pyrender_light(pr, lt, shadows) for lt in scene.lights]
            self._light_nodes = [self._scene.add(light, name=f"light:{i:03d}", pose=pose)
                                 for i, (light, pose) in enumerate(lights)]
            self._lights = scene.lights

    def _add_label_nodes(self, item: MeshItem) -> list:
        out = []
        for faces, mat in _groups(item, lambda m: m.label):
            mesh = _pyrender_mesh(self.pyrender, item, faces, mat, self._textures)
            mesh.is_visible = False
            out.append((self._scene.add(mesh, name=f"label:{mesh.name}"), _label_color(mat.label)))
        return out

    def _drop(self, entry: dict) -> None:
        for node in entry["colour"]:
            self._scene.remove_node(node)
        for node, _ in entry["label"] or ():
            self._scene.remove_node(node)

    def _label_nodes(self) -> list:
        return [pair for entry in self._items.values() for pair in entry["label"] or ()]

    # ---- rendering ------------------------------------------------------------------------
    @single_threaded  # pyrender inverts a 4x4 per view: 2 BLAS threads cost ~30 ms of it under load
    def render_views(self, scene: Scene, depth: bool = False, labels: bool = False):
        """The corrected (virtual, real) view images, as :meth:`MirrorRig.split_views` returns them.

        Returns a list of ``(color (h, w, 3) uint8, depth (h, w) float32 or None, labels or None)``
        per view, in :data:`~lipgen.rig.camera.VIEWS` order (no mirror dimming).
        """
        self._sync(scene, labels)
        drawn = None
        if self._one_pass:
            drawn = _onepass.render_side_by_side(self._renderer, self._scene,
                                                 [(v.node, *v.size) for v in self._views], self._flags, depth)
        out = []
        for k, v in enumerate(self._views):
            self._scene.main_camera_node = v.node
            self._renderer.viewport_width, self._renderer.viewport_height = v.size
            color, z = drawn[k] if drawn else self._renderer.render(self._scene, flags=self._flags)
            color, z = v.resample(color, z if depth else None)
            out.append([color, z, self._render_labels(v, scene) if labels else None])
        return out

    def _render_labels(self, v: _View, scene: Scene) -> np.ndarray:
        pairs = self._label_nodes()
        for node, _ in pairs:
            node.mesh.is_visible = True
        try:
            seg, _ = self._renderer.render(self._scene, flags=self.pyrender.RenderFlags.SEG,
                                           seg_node_map=dict(pairs))
        finally:
            for node, _ in pairs:
                node.mesh.is_visible = False
        if v.cam.dist is not None:
            seg = seg.reshape(-1, 3)[v.nearest].reshape(v.cam.height, v.cam.width, 3)
        return _decode_labels(seg, sorted({m.label for it in scene.items for m in it.materials}))

    def render(self, scene: Scene, depth: bool = False, labels: bool = False) -> RenderedFrame:
        """One raw frame of ``scene`` as the rig's real camera sees it."""
        (cv, zv, lv), (cr, zr, lr) = self.render_views(scene, depth, labels)
        dimmed = _dimming_table(self.reflectance)[cv]  # the same float32 rounding, per value
        image = self.rig.compose(dimmed, cr)
        return RenderedFrame(image, self.rig.compose(zv, zr) if depth else None,
                             self.rig.compose(lv, lr) if labels else None)

    def clear(self) -> None:
        """Drop every scene item, texture and light, keeping the OpenGL context and the views:
        the renderer is then as new, for another subject seen by the same rig."""
        for entry in self._items.values():
            self._drop(entry)
        self._items.clear()
        self._textures.clear()
        for node in self._light_nodes:
            self._scene.remove_node(node)
        self._light_nodes, self._lights = [], ()

    def close(self) -> None:
        """Release the OpenGL context."""
        if getattr(self, "_renderer", None) is not None:
            self._renderer.delete()
            self._renderer = None

    def __enter__(self) -> RigRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@functools.lru_cache(maxsize=8)
def _dimming_table(reflectance: float) -> np.ndarray:
    """(256,) uint8: ``round(v * reflectance)`` in float32 for every 8-bit value ``v``."""
    return np.round(np.arange(256, dtype=np.float32) * np.float32(reflectance)).astype(np.uint8)


def _ordered_scene(pr):
    """A pyrender Scene that hands out its nodes sorted by name.

    pyrender keeps nodes in sets, which iterate in an order set by memory addresses; the sum
    over lights and the draw order would then change from process to process, and with them
    the last bit of some pixels. Sorted, the same scene gives the same bytes everywhere.
    """

    def key(node):
        return node.name or ""

    class OrderedScene(pr.Scene):
        @property
        def mesh_nodes(self):
            return sorted(self._mesh_nodes, key=key)

        @property
        def point_light_nodes(self):
            return sorted(self._point_light_nodes, key=key)

        @property
        def spot_light_nodes(self):
            return sorted(self._spot_light_nodes, key=key)

        @property
        def directional_light_nodes(self):
            return sorted(self._directional_light_nodes, key=key)

        @property
        def light_nodes(self):
            return sorted(self._point_light_nodes | self._spot_light_nodes | self._directional_light_nodes,
                          key=key)

    return OrderedScene


def _fingerprint(item: MeshItem) -> str:
    h = hashlib.blake2b(digest_size=16)
    for a in (item.vertices, item.faces, item.normals, item.face_material):
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(repr([m.key for m in item.materials]).encode())
    if item.uv is not None:
        h.update(np.ascontiguousarray(item.uv).tobytes())
    return h.hexdigest()


def _groups(item: MeshItem, key) -> list[tuple[np.ndarray, object]]:
    """Faces of ``item`` grouped by ``key(material)``: ``[(faces (k, 3), first material), ...]``."""
    keys = [key(m) for m in item.materials]
    first = {}
    for i, k in enumerate(keys):
        first.setdefault(k, i)
    group_of_material = np.array([list(first).index(k) for k in keys])
    g = group_of_material[item.face_material]
    return [(item.faces[g == j], item.materials[i]) for j, i in enumerate(first.values()) if (g == j).any()]


def _pyrender_mesh(pr, item: MeshItem, faces: np.ndarray, mat, textures: dict | None = None):
    """A pyrender mesh of some of ``item``'s faces with material ``mat`` (compact vertex buffer).

    ``textures`` caches pyrender textures by image, so a texture shared by every frame stays on
    the GPU (pyrender uploads a texture object once while some mesh uses it)."""
    used, inv = np.unique(faces, return_inverse=True)
    textured = mat.texture is not None and item.uv is not None
    tex = None
    if textured:
        cache = {} if textures is None else textures
        if id(mat.texture) not in cache:
            cache[id(mat.texture)] = (mat.texture, pr.Texture(source=mat.texture, source_channels="RGB"))
        tex = cache[id(mat.texture)][1]
    material = pr.MetallicRoughnessMaterial(
        baseColorFactor=np.append(srgb_to_linear(mat.color), mat.opacity), metallicFactor=0.0,
        roughnessFactor=mat.roughness, doubleSided=mat.double_sided, baseColorTexture=tex,
        alphaMode="BLEND" if mat.opacity < 1 else None)
    prim = pr.Primitive(positions=item.vertices[used].astype(np.float32),
                        normals=item.normals[used].astype(np.float32),
                        texcoord_0=item.uv[used].astype(np.float32) if textured else None,
                        indices=inv.reshape(-1, 3).astype(np.uint32), material=material)
    return pr.Mesh([prim], name=f"{item.name}:{mat.name}")


_FAR = 1e5  # mm: a point light this far stands in for a directional light that casts no shadow


def _pyrender_light(pr, light, shadows: bool = False) -> tuple:
    """A pyrender light and its pose. When shadows are drawn, a directional light that casts none
    becomes a point light ``_FAR`` mm away along its direction, as bright at the scene (pyrender
    draws shadows for every directional light or none)."""
    color = srgb_to_linear(light.color)
    pose = np.eye(4)
    if light.kind == "directional" and shadows and not light.shadows:
        d = np.asarray(light.direction, float)
        pose[:3, 3] = -_FAR * d / np.linalg.norm(d)
        return pr.PointLight(color=color, intensity=light.intensity * _FAR**2), pose
    if light.kind == "directional":
        z = -np.asarray(light.direction, float)
        z /= np.linalg.norm(z)
        x = np.cross([0.0, 1.0, 0.0], z)
        x = x / np.linalg.norm(x) if np.linalg.norm(x) > 1e-9 else np.array([1.0, 0, 0])
        pose[:3, :3] = np.stack([x, np.cross(z, x), z], 1)
        return _shadow_light_class(pr)(color=color, intensity=light.intensity), pose
    pose[:3, 3] = light.position
    return pr.PointLight(color=color, intensity=light.intensity), pose


_SHADOW_DEPTH_RANGE = 40.0


def _shadow_light_class(pr):
    """pyrender's directional light with a deeper shadow-map camera (no shadow acne).

    pyrender's fragment shader offsets each depth comparison by 1e-4 to 1e-3 (slope-scaled) of the
    shadow camera's depth range, which it sets to 10 scene sizes: on a finely curved face lit at a
    grazing angle that is less than the depth step between shadow-map texels, and the surface
    shadows itself in stripes (acne). A range of 40 scene sizes makes the offset 0.4-4 % of the
    scene (about 1-10 mm on a face, less than the nose's or the lips' relief), with depth
    precision to spare (24 bits over 40 scene sizes).
    """
    cls = getattr(pr, "_lipgen_shadow_light", None)
    if cls is None:
        class ShadowDirectionalLight(pr.DirectionalLight):
            def _get_shadow_camera(self, scene_scale):
                return pr.OrthographicCamera(znear=0.01 * scene_scale, zfar=_SHADOW_DEPTH_RANGE * scene_scale,
                                             xmag=scene_scale, ymag=scene_scale)

        cls = pr._lipgen_shadow_light = ShadowDirectionalLight
    return cls


_PALETTE_STEP = np.array([1, 89, 157])


def _label_color(label: int) -> np.ndarray:
    """A distinct 8-bit colour per label (far apart, so blended edge pixels decode sensibly)."""
    return (int(label) * _PALETTE_STEP) % 256


def _decode_labels(seg: np.ndarray, labels: list[int]) -> np.ndarray:
    """Labels from a segmentation render: the nearest colour among the scene's labels and the
    black background (edge pixels blend neighbouring colours)."""
    ids = np.array([0, *labels])
    palette = np.stack([_label_color(k) for k in ids]).astype(np.int32)
    packed = (seg[..., 0].astype(np.int32) << 16) | (seg[..., 1].astype(np.int32) << 8) | seg[..., 2]
    keys, inv = np.unique(packed.ravel(), return_inverse=True)
    colors = np.stack([keys >> 16, (keys >> 8) & 255, keys & 255], 1)
    d = ((colors[:, None, :] - palette[None]) ** 2).sum(axis=2)
    return ids[np.argmin(d, axis=1)].astype(np.uint8)[inv.ravel()].reshape(seg.shape[:2])
