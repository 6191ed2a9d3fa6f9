"""Photoreal rendering of the camera-mirror rig with Blender Cycles (the only rig module importing bpy).

:class:`CyclesRenderer` draws the same :class:`~lipgen.rig.scene.Scene` as the pyrender
:class:`~lipgen.rig.render.RigRenderer`, through the same view cameras: each half of the raw
frame is rendered from its own view camera (the mirror half from the virtual camera, the real
camera reflected in the mirror plane), so its pixels agree with :meth:`MirrorRig.project` exactly
as pyrender's do, and :meth:`MirrorRig.compose` flips the mirror half into place. Lens
distortion is applied as in pyrender, by resampling a wider pinhole render.

Depth and label masks are geometry: which surface each pixel's line of sight meets first, and
how far along the view camera's axis. They do not depend on the light transport, so they are
rasterised by pyrender (:class:`~lipgen.rig.render.RigRenderer`, opened when first asked for)
from the same :class:`~lipgen.rig.scene.Scene` through the same view cameras and lens resampling:
the same bytes as a pyrender dataset's depth and masks of that scene.

What Cycles adds: path-traced light (soft shadows from the world light in folds and the mouth,
inter-reflection), and subsurface scattering in skin and lips. The scene description carries no
subsurface parameters; tissue materials are recognised by name (:data:`SUBSURFACE`).

Conventions: one Blender unit is one millimetre; Blender cameras look down -z with y up (as
OpenGL), and a lens shift of 0 puts the principal point at the image centre, OpenCV's
``(w - 1) / 2``. Light units follow pyrender's shader: a directional light of intensity E gives a
white Lambertian surface facing it the radiance ``E / pi`` (a Cycles sun of strength E), and the
ambient light A is a uniform world radiance A seen by everything but the camera, which sees the
scene's background colour; a point light of pyrender intensity I is a Cycles point of power
``4 pi I``. Measured on a grey matte plane, the two renderers agree within 4-7 % in linear light
(``tests/test_cycles.py``).
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import tempfile

import numpy as np

from lipgen._optional import require
from lipgen.errors import RenderBackendError
from lipgen.rig.camera import MirrorRig
from lipgen.rig.cycles_nodes import _image, _matrix, _principled, _set_geometry, _world_nodes
from lipgen.rig.imaging import srgb_encode
from lipgen.rig.pinhole import PinholeCamera
from lipgen.rig.render import RenderedFrame
from lipgen.rig.resample import PinholeWindow
from lipgen.rig.scene import Material, MeshItem, Scene, srgb_to_linear

__all__ = ["CyclesRenderer", "SUBSURFACE", "import_bpy"]

log = logging.getLogger(__name__)

_OPEN: list = []  # the CyclesRenderer holding this process's Blender session, if any

SUBSURFACE: dict[str, tuple[float, float, float]] = {
    "skin": (3.67, 1.37, 0.68),
    "vermilion": (3.67, 1.37, 0.68),
    "mucosa": (3.67, 1.37, 0.68),
    "lip": (3.67, 1.37, 0.68),
    "tongue": (3.67, 1.37, 0.68),
    "gums": (3.67, 1.37, 0.68),
}
"""Subsurface scattering distance (R, G, B) in mm of the tissue materials, by material name.

Jensen et al. (2001, "A practical model for subsurface light transport", Table 1, "Skin1"):
diffuse mean free path ``1 / sigma_tr`` = 3.67, 1.37, 0.68 mm, from the measured scattering and
absorption coefficients of skin. Lips and the oral mucosa have no published measurement of their
own here and use the skin's. Other materials (ink, cavity, teeth, the chessboard) scatter none."""


def import_bpy():
    """Import Blender's ``bpy`` module (``pip install 'lipgen[blender]'``).

    Raises
    ------
    MissingDependencyError
        bpy is not installed (it needs Python 3.11).
    """
    with _quiet():  # its first import logs to standard output (the GPU libraries it did not find)
        return require("bpy", "rendering with Blender Cycles (--renderer cycles)")


@contextlib.contextmanager
def _quiet():
    """Blender writes its render log ("Fra:", "Saved:") to the process's standard output; the
    library prints nothing, so file descriptor 1 points at the null device meanwhile."""
    sys.stdout.flush()
    saved = os.dup(1)
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(null)
        os.close(saved)


class _View:
    """One view camera as Cycles renders it, with the resampling map when it has distortion."""

    def __init__(self, bpy, cam: PinholeCamera, znear: float, zfar: float, name: str) -> None:
        K = cam.K
        if not np.isclose(K[0, 0], K[1, 1], rtol=1e-9):
            raise ValueError(f"{cam.name}: the Cycles renderer needs square pixels (fx = fy), got "
                             f"fx={K[0, 0]}, fy={K[1, 1]}")
        self.cam = cam
        self.window = PinholeWindow(cam)  # as pyrender's view: a wider pinhole render, resampled
        x0, y0 = self.window.offset
        w, h = self.size = self.window.size
        data = bpy.data.cameras.new(name)
        data.sensor_fit = "HORIZONTAL"
        data.sensor_width = 36.0
        data.lens = K[0, 0] * 36.0 / w
        # shift, in units of the image width (horizontal fit), moves the frame: a frame moved right
        # sees the optical axis left of the image centre (and one moved up sees it lower)
        data.shift_x = -(K[0, 2] - x0 + 0.5 - w / 2) / w
        data.shift_y = (K[1, 2] - y0 + 0.5 - h / 2) / w
        data.clip_start, data.clip_end = znear, zfar
        self.obj = bpy.data.objects.new(name, data)
        pose = np.eye(4)
        pose[:3, :3] = cam.R.T @ np.diag([1.0, -1.0, -1.0])
        pose[:3, 3] = cam.center
        self.pose = pose

    def resample(self, lin: np.ndarray) -> np.ndarray:
        return self.window.resample(lin)


class CyclesRenderer:
    """Renders :class:`~lipgen.rig.scene.Scene` s through a :class:`~lipgen.rig.camera.MirrorRig`
    with Blender Cycles on the CPU; the same interface as :class:`~lipgen.rig.render.RigRenderer`.

    bpy holds one Blender session per process: make one renderer per process and reuse it (it
    resets the session to an empty file when made). Meshes are updated in place when only their
    vertices and normals change.

    Parameters
    ----------
    rig : MirrorRig
    mirror_reflectance : float
        Fraction of light the mirror returns.
    znear, zfar : float
        Clipping depths, mm.
    shadows : bool
        The scene's lights cast shadows (the world's ambient light always does: ambient occlusion).
    samples : int
        Path-tracing samples per pixel.
    denoise : bool
        Denoise with OpenImageDenoise (when this Blender build has it).
    threads : int
        CPU threads Cycles uses; 0 for all cores.
    seed : int
        Cycles' sampling seed (the same seed and samples give the same pixels).
    """

    def __init__(self, rig: MirrorRig, mirror_reflectance: float = 0.9, znear: float = 20.0,
                 zfar: float = 5000.0, shadows: bool = False, samples: int = 16, denoise: bool = True,
                 threads: int = 0, seed: int = 0) -> None:
        if not isinstance(rig, MirrorRig):
            raise TypeError(f"rig must be a MirrorRig, got {type(rig).__name__}")
        if not 0 < mirror_reflectance <= 1:
            raise ValueError(f"mirror_reflectance must be in (0, 1], got {mirror_reflectance}")
        for name, v, lo, hi in (("samples", samples, 1, 4096), ("threads", threads, 0, 1024),
                                ("seed", seed, 0, 2**31 - 1)):
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or not lo <= v <= hi:
                raise ValueError(f"{name} must be a whole number in [{lo}, {hi}], got {v!r}")
        self.rig, self.reflectance, self.shadows = rig, float(mirror_reflectance), bool(shadows)
        self.bpy = import_bpy()
        if _OPEN:
            raise RenderBackendError("bpy holds one Blender session per process and another CyclesRenderer "
                                     "is open in it: close() that one first")
        with _quiet():  # Cycles logs its devices to standard output when it first starts
            self._open(samples, denoise, threads, seed, znear, zfar)
        self._tmp = tempfile.TemporaryDirectory(prefix="lipgen-cycles-")
        _OPEN.append(self)
        self._items: dict[str, dict] = {}
        self._materials: dict[tuple, object] = {}
        self._textures: dict[int, tuple] = {}
        self._lights: tuple | None = None
        self._light_objs: list = []
        self._env: tuple | None = None
        self._clip = (znear, zfar)
        self._geometry = None  # pyrender, for depth and labels

    def _open(self, samples, denoise, threads, seed, znear, zfar) -> None:
        bpy = self.bpy
        bpy.ops.wm.read_factory_settings(use_empty=True)
        sc = self._scene = bpy.data.scenes[0]
        sc.render.engine = "CYCLES"
        cy = sc.cycles
        cy.device, cy.samples, cy.seed = "CPU", int(samples), int(seed)
        cy.use_adaptive_sampling = False
        cy.use_denoising = bool(denoise) and _has_oidn(bpy)
        if denoise and not cy.use_denoising:
            log.warning("this Blender build has no OpenImageDenoise: Cycles renders without denoising")
        if cy.use_denoising:
            cy.denoiser = "OPENIMAGEDENOISE"
        self.denoise = cy.use_denoising
        sc.render.threads_mode = "AUTO" if threads == 0 else "FIXED"
        if threads:
            sc.render.threads = int(threads)
        sc.render.resolution_percentage = 100
        sc.render.film_transparent = False
        # persistent data would keep Cycles' scene between renders, but its updates made the pixels
        # depend on what was rendered before (measured: up to 60 grey levels); off, the same
        # scene, samples and seed give the same bytes
        sc.render.use_persistent_data = False
        sc.view_settings.view_transform = "Standard"
        st = sc.render.image_settings
        st.file_format, st.color_depth, st.exr_codec = "OPEN_EXR", "32", "NONE"
        self._world = bpy.data.worlds.new("lipgen-world")
        sc.world = self._world
        self._views = [_View(bpy, cam, znear, zfar, f"view:{cam.name}") for cam in self.rig.views]
        for v in self._views:
            sc.collection.objects.link(v.obj)
            v.obj.matrix_world = _matrix(v.pose)

    # ---- scene sync -----------------------------------------------------------------------
    def _sync(self, scene: Scene) -> None:
        env = (tuple(scene.ambient), tuple(scene.background))
        if env != self._env:
            _world_nodes(self._world, srgb_to_linear(scene.ambient), srgb_to_linear(scene.background))
            self._env = env
        wanted = {it.name: it for it in scene.items}
        for name in list(self._items):
            if name not in wanted:
                self._drop(self._items.pop(name))
        for name, item in wanted.items():
            key = (item.faces.shape, item.faces.tobytes(), item.face_material.tobytes(),
                   tuple(m.key for m in item.materials), item.uv is None)
            entry = self._items.get(name)
            if entry is not None and entry["key"] != key:
                self._drop(self._items.pop(name))
                entry = None
            if entry is None:
                entry = self._items[name] = {"key": key, "obj": self._new_object(item)}
            _set_geometry(entry["obj"].data, item)
        if scene.lights != self._lights:
            bpy = self.bpy
            for obj in self._light_objs:
                data = obj.data
                bpy.data.objects.remove(obj)
                bpy.data.lights.remove(data)
            self._light_objs = [self._new_light(i, lt) for i, lt in enumerate(scene.lights)]
            self._lights = scene.lights

    def _new_object(self, item: MeshItem):
        bpy = self.bpy
        me = bpy.data.meshes.new(item.name)
        n, m = len(item.vertices), len(item.faces)
        me.vertices.add(n)
        me.loops.add(3 * m)
        me.polygons.add(m)
        me.loops.foreach_set("vertex_index", item.faces.astype(np.int32).ravel())
        me.polygons.foreach_set("loop_start", np.arange(0, 3 * m, 3, dtype=np.int32))
        me.polygons.foreach_set("material_index", item.face_material.astype(np.int32))
        me.polygons.foreach_set("use_smooth", np.ones(m, bool))
        for mat in item.materials:
            me.materials.append(self._material(mat))
        if item.uv is not None:
            layer = me.uv_layers.new(name="uv")
            layer.data.foreach_set("uv", item.uv[item.faces.ravel()].astype(np.float32).ravel())
        obj = bpy.data.objects.new(item.name, me)
        self._scene.collection.objects.link(obj)
        return obj

    def _drop(self, entry: dict) -> None:
        me = entry["obj"].data
        self.bpy.data.objects.remove(entry["obj"])
        self.bpy.data.meshes.remove(me)

    def _material(self, mat: Material):
        key = mat.key + (mat.name in SUBSURFACE,)
        if key not in self._materials:
            tex = None
            if mat.texture is not None:
                if id(mat.texture) not in self._textures:
                    self._textures[id(mat.texture)] = (mat.texture, _image(self.bpy, mat.texture))
                tex = self._textures[id(mat.texture)][1]
            self._materials[key] = _principled(self.bpy, mat, tex, SUBSURFACE.get(mat.name))
        return self._materials[key]

    def _new_light(self, i: int, lt):
        bpy = self.bpy
        if lt.kind == "directional":
            data = bpy.data.lights.new(f"light:{i:03d}", "SUN")
            data.energy = float(lt.intensity)  # irradiance, as pyrender's directional intensity
            data.angle = 0.0
            pose = np.eye(4)
            z = -np.asarray(lt.direction, float)
            z /= np.linalg.norm(z)
            x = np.cross([0.0, 1.0, 0.0], z)
            x = x / np.linalg.norm(x) if np.linalg.norm(x) > 1e-9 else np.array([1.0, 0, 0])
            pose[:3, :3] = np.stack([x, np.cross(z, x), z], 1)
        else:
            data = bpy.data.lights.new(f"light:{i:03d}", "POINT")
            # pyrender: radiance intensity / d^2 (candela-like); Cycles: power P spread over 4 pi sr
            data.energy = float(4 * np.pi * lt.intensity)
            data.shadow_soft_size = 0.0
            pose = np.eye(4)
            pose[:3, 3] = lt.position
        data.color = tuple(float(c) for c in srgb_to_linear(lt.color))
        data.use_shadow = self.shadows and lt.shadows  # fill lights cast none (as in pyrender)
        obj = bpy.data.objects.new(data.name, data)
        self._scene.collection.objects.link(obj)
        obj.matrix_world = _matrix(pose)
        return obj

    # ---- rendering ------------------------------------------------------------------------
    def _render_linear(self, v: _View) -> np.ndarray:
        bpy, sc = self.bpy, self._scene
        sc.camera = v.obj
        sc.render.resolution_x, sc.render.resolution_y = v.size
        path = os.path.join(self._tmp.name, "view.exr")
        sc.render.filepath = path
        with _quiet():
            bpy.ops.render.render(write_still=True, scene=sc.name)
        img = bpy.data.images.load(path, check_existing=False)
        try:
            w, h = v.size
            px = np.empty(w * h * 4, np.float32)
            img.pixels.foreach_get(px)
        finally:
            bpy.data.images.remove(img)
        lin = np.ascontiguousarray(px.reshape(h, w, 4)[::-1, :, :3])  # Blender's rows run bottom-up
        return v.resample(lin)

    def render_views(self, scene: Scene, depth: bool = False, labels: bool = False):
        """The corrected (virtual, real) view images, as :meth:`MirrorRig.split_views` returns them.

        Returns a list of ``(color (h, w, 3) uint8, depth (h, w) float32 or None, labels (h, w)
        uint8 or None)`` per view, in :data:`~lipgen.rig.camera.VIEWS` order (no mirror dimming).
        Depth (view-camera z, mm; 0 where nothing was drawn) and labels are rasterised by pyrender
        from the same scene (see the module docstring).
        """
        if not isinstance(scene, Scene):
            raise TypeError(f"scene must be a lipgen.rig.scene.Scene, got {type(scene).__name__}")
        self._sync(scene)
        out = [[srgb_encode(self._render_linear(v)), None, None] for v in self._views]
        if depth or labels:
            if self._geometry is None:
                from lipgen.rig.render import RigRenderer

                self._geometry = RigRenderer(self.rig, self.reflectance, *self._clip)
            for view, (_, z, lab) in zip(out, self._geometry.render_views(scene, depth, labels), strict=True):
                view[1], view[2] = z, lab
        return out

    def render(self, scene: Scene, depth: bool = False, labels: bool = False) -> RenderedFrame:
        """One raw frame of ``scene`` as the rig's real camera sees it (depth and labels as
        :meth:`render_views`)."""
        (cv, zv, lv), (cr, zr, lr) = self.render_views(scene, depth, labels)
        dimmed = np.round(cv.astype(np.float32) * self.reflectance).astype(np.uint8)
        compose = self.rig.compose
        return RenderedFrame(compose(dimmed, cr), compose(zv, zr) if depth else None,
                             compose(lv, lr) if labels else None)

    def close(self) -> None:
        """Empty the Blender session and remove the temporary folder."""
        if getattr(self, "_geometry", None) is not None:
            self._geometry.close()
            self._geometry = None
        if getattr(self, "_tmp", None) is not None:
            with _quiet():
                self.bpy.ops.wm.read_factory_settings(use_empty=True)
            self._tmp.cleanup()
            self._tmp = None
            _OPEN.remove(self)

    def __enter__(self) -> CyclesRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _has_oidn(bpy) -> bool:
    try:
        import _cycles

        return bool(_cycles.with_openimagedenoise)
    except (ImportError, AttributeError):
        return False
