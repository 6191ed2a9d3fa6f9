"""Offscreen rendering of the camera-mirror rig with pyrender (the only module importing pyrender).

One raw frame is what the real camera sees (thesis Fig 3-3): the face directly in one half and
its reflection in the mirror in the other, flipped left-right. Each half is rendered from its
own view camera (:attr:`MirrorRig.real_view`, :attr:`MirrorRig.virtual_view`), so the pixels
agree exactly with :meth:`MirrorRig.project`; the mirror half is then flipped into place by
:meth:`MirrorRig.compose` and dimmed by the mirror's reflectance. The two halves together have
as many pixels as one full frame.

OpenGL conventions stay in this module: pyrender's cameras look down -z with y up, and its
principal point is measured from the pixel corner (OpenCV's from the pixel centre, hence +0.5).
Radial distortion, which OpenGL cannot draw, is applied by resampling a wider pinhole render
(:class:`~lipgen.rig.resample.PinholeWindow`, shared with the Cycles renderer). How a scene becomes
pyrender meshes and lights is in :mod:`lipgen.rig._pyscene`.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass

import numpy as np

from lipgen._optional import require
from lipgen._threads import single_threaded
from lipgen.errors import MissingDependencyError, RenderBackendError
from lipgen.rig import _onepass, _shadowmap
from lipgen.rig._pyscene import (
    _decode_labels,
    _fingerprint,
    _groups,
    _label_color,
    _ordered_scene,
    _pyrender_light,
    _pyrender_mesh,
    _set_vertices,
    _upload_vertices,
    delete_offscreen,
    internals_known,
)
from lipgen.rig.camera import MirrorRig
from lipgen.rig.pinhole import PinholeCamera
from lipgen.rig.resample import PinholeWindow
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
    """A view camera as pyrender draws it: the pinhole window it is resampled from (lens distortion)."""

    def __init__(self, pyrender, cam: PinholeCamera, znear: float, zfar: float) -> None:
        self.cam = cam
        self.window = PinholeWindow(cam)
        self.size = self.window.size
        K = cam.K
        x0, y0 = self.window.offset
        gl = pyrender.IntrinsicsCamera(K[0, 0], K[1, 1], K[0, 2] - x0 + 0.5, K[1, 2] - y0 + 0.5, znear, zfar)
        pose = np.eye(4)
        pose[:3, :3] = cam.R.T @ np.diag([1.0, -1.0, -1.0])
        pose[:3, 3] = cam.center
        self.node = pyrender.Node(camera=gl, matrix=pose)

    def resample(self, color: np.ndarray, depth: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
        return self.window.resample(color), None if depth is None else self.window.resample_nearest(depth)


class RigRenderer:
    """Renders :class:`~lipgen.rig.scene.Scene` s through a :class:`~lipgen.rig.camera.MirrorRig`.

    Holds one offscreen OpenGL context (EGL) for its lifetime; make one per process and reuse
    it. Geometry is uploaded again only for items whose arrays changed (vertex buffers in place).

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
    samples : int
        Multisampling (anti-aliasing) samples per pixel: pyrender's 4, or 0 for none (edges
        aliased; on llvmpipe about half the CPU of a ``hard`` render, ``lipgen bench --suite
        presets``, ``msaa``). Other counts are rounded up by the GL driver. Needs ``one_pass``.
    """

    def __init__(self, rig: MirrorRig, mirror_reflectance: float = 0.9, znear: float = 20.0,
                 zfar: float = 5000.0, shadows: bool = False, one_pass: bool = True,
                 samples: int = 4) -> None:
        if not isinstance(rig, MirrorRig):
            raise TypeError(f"rig must be a MirrorRig, got {type(rig).__name__}")
        if not 0 < mirror_reflectance <= 1:
            raise ValueError(f"mirror_reflectance must be in (0, 1], got {mirror_reflectance}")
        _check_samples(samples)
        if samples != 4 and not one_pass:
            raise ValueError(f"samples={samples} needs the one-pass renderer (one_pass=True); pyrender's own "
                             "passes multisample 4 times")
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
        if samples != 4:
            if not self._one_pass:
                self.close()
                raise RenderBackendError(f"samples={samples} needs lipgen's one-pass renderer, which this "
                                         f"pyrender or GL platform does not take; use samples=4")
            self.samples = samples
        self._in_place = internals_known(pr)  # else every moved item is rebuilt
        if shadows:  # pyrender's shadow filter in 16 depth reads, not 36: the same pixels
            _shadowmap.install(self._renderer)
        self._scene = _ordered_scene(pr)()
        for v in self._views:
            self._scene.add_node(v.node)
        self._items: dict[str, dict] = {}
        self._textures: dict[int, tuple] = {}  # id(array) -> (array, pyrender Texture): uploaded once
        self._lights: tuple = ()
        self._light_nodes: list = []

    @property
    def samples(self) -> int:
        """Multisampling samples per pixel (see the class parameters); settable between renders."""
        return self._renderer._renderer.samples if self._one_pass else 4

    @samples.setter
    def samples(self, value: int) -> None:
        _check_samples(value)
        if value != self.samples:
            if not self._one_pass:
                raise RenderBackendError(f"samples={value} needs lipgen's one-pass renderer; use samples=4")
            r = self._renderer
            r._platform.make_current()
            try:
                r._renderer._delete_main_framebuffer()  # made again, with the new count, at the next render
            finally:
                r._platform.make_uncurrent()
            r._renderer.samples = int(value)

    # ---- scene sync -----------------------------------------------------------------------
    def _sync(self, scene: Scene, labels: bool) -> None:
        """Bring the pyrender scene up to date; upload only items whose arrays changed.

        An item whose faces, materials and uv are unchanged keeps its pyrender meshes, and only
        their vertex buffers are written again (in place): a moving subject builds no new
        meshes, vertex arrays or programs frame after frame.

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
        moved = []
        for name, item in wanted.items():
            key, geometry = _fingerprint(item)
            old = self._items.get(name)
            if old is not None and old["key"] == key and self._in_place:  # the same meshes, perhaps moved
                if old["geometry"] != geometry:
                    nodes = old["colour"] + [node for node, _ in old["label"] or ()]
                    moved += [n.mesh.primitives[0] for n in nodes if _set_vertices(n.mesh, item)]
                    old["geometry"] = geometry
                    self._scene._bounds = None
                if labels and old["label"] is None:
                    old["label"] = self._add_label_nodes(item)
                continue
            if old is not None:
                self._drop(old)
            groups = _groups(item, lambda m: (m.color, m.roughness, m.double_sided,
                                              None if m.texture is None else id(m.texture), m.opacity))
            meshes = [_pyrender_mesh(pr, item, faces, mat, self._textures) for faces, mat in groups]
            colour = [self._scene.add(m, name=m.name) for m in meshes]
            self._items[name] = {"key": key, "geometry": geometry, "colour": colour,
                                 "label": self._add_label_nodes(item) if labels else None}
        if moved:
            self._renderer._platform.make_current()
            try:
                _upload_vertices(moved)
            finally:
                self._renderer._platform.make_uncurrent()
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
        seg = v.window.resample_nearest(seg)
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
            delete_offscreen(self.pyrender, self._renderer)
            self._renderer = None

    def __enter__(self) -> RigRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _check_samples(samples) -> None:
    if isinstance(samples, bool) or not isinstance(samples, int | np.integer) or not 0 <= samples <= 16:
        raise ValueError(f"samples must be a whole number of samples per pixel in [0, 16], got {samples!r}")


@functools.lru_cache(maxsize=8)
def _dimming_table(reflectance: float) -> np.ndarray:
    """(256,) uint8: ``round(v * reflectance)`` in float32 for every 8-bit value ``v``."""
    return np.round(np.arange(256, dtype=np.float32) * np.float32(reflectance)).astype(np.uint8)
