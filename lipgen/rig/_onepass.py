"""Both view cameras of the rig drawn in one forward pass into one framebuffer, read back once.

pyrender draws one camera per ``render`` call: it binds and clears the framebuffer, and for every
primitive binds its program, the camera, every light and the material, then draws; then it
resolves the multisampled buffer and reads depth (linearised in numpy) and colour back. The rig
needs two cameras (the real and the virtual view) whose images are the two halves of one raw
frame, so it paid all of that twice, and read a depth map nobody asked for.

Here the two views sit side by side in one framebuffer: each primitive is bound once (program,
lights, shadow maps) and drawn once per view, with that view's camera uniforms, viewport and
scissor box. The resolve and the read-back happen once, and depth is resolved and read only when
asked for. pyrender's shaders, materials and light binding are used as they are: the renderer
object gets a subclass of :class:`pyrender.Renderer` that overrides the forward pass while
``views`` is set, and a plain render (the label pass, any other caller) is pyrender's.

pyrender sorts meshes by the distance of their node origin from the camera, and the draw order
decides ties in depth. When the two cameras would sort them differently, the two views are
rendered one after the other as before, so the pixels never depend on this module.

The lighting loops (issue 22). pyrender's ``mesh.frag`` loops over ``n_directional_lights``,
``n_point_lights`` and ``n_spot_lights``, uniforms. llvmpipe (Mesa's software GL) runs such a loop
as a divergent one, with per-lane masks, and reads ``directional_lights[i]`` with a dynamic index,
per lane. The one-pass renderer compiles a copy of the shader whose loops run to compile-time
bounds, the light counts pyrender binds (``fixed_light_shader``; one program per mix of light
kinds), so the loops unroll and the light uniforms are read at constant indices. The arithmetic
and its order are the same: the frames are byte-identical (``tests/test_render_onepass.py``, with
and without shadows and for three light mixes; ``lipgen generate`` frames of the easy, default and
hard presets, seed 7, PNGs identical to main's). Measured on the render bench's frame (CPU,
medians of 10 interleaved rounds, ``LP_NUM_THREADS=1``, load 7.4): both views in one pass 1.50 of
one full-frame pyrender pass with pyrender's shader, 0.73 with the fixed loops. The full-frame
pass stays pyrender's own (a plain ``render`` uses pyrender's program cache and shader).
``lipgen bench --suite render`` (30 interleaved rounds, ``LP_NUM_THREADS=1``): ``ratio_to_limit``
1.25 and 1.35 in two runs (load 9-12), the raw frame 0.76 and 0.73 of the single pass's CPU;
main in the same hour read 0.656 and 1.51 (load 12.5-14.7). A hard render costs 0.52 of its CPU
before (0.225 -> 0.114 s), an easy one 0.46 (``lipgen.bench.preset_frames``).
"""

from __future__ import annotations

import atexit
import functools
import hashlib
import logging
import os
import shutil
import tempfile

import numpy as np

__all__ = ["install", "render_side_by_side", "fixed_light_shader"]

log = logging.getLogger(__name__)


def _one_pass_class(pr):
    from OpenGL import GL
    from pyrender.constants import ProgramFlags

    class OnePassRenderer(pr.Renderer):
        """pyrender's renderer that can draw several cameras side by side in one forward pass."""

        views = None  # [(camera node, (x, y, w, h)), ...] while drawing side by side
        want_depth = False
        order = None  # the mesh nodes in draw order, sorted once for all the views
        samples = 4  # multisampling of the main framebuffer (pyrender's 4)
        fixed_lights = True  # light loops with bounds fixed at compile time (same pixels, less CPU)
        _lipgen_fixed_cache = None

        def _forward_pass(self, scene, flags, seg_node_map=None):
            if self.views is None:
                return super()._forward_pass(scene, flags, seg_node_map)
            self.viewport_width = W = sum(r[2] for _, r in self.views)
            self.viewport_height = H = max(r[1] + r[3] for _, r in self.views)
            self._configure_main_framebuffer()
            GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, self._main_fb_ms)
            GL.glViewport(0, 0, W, H)
            GL.glEnable(GL.GL_DEPTH_TEST)
            GL.glDepthMask(GL.GL_TRUE)
            GL.glDepthFunc(GL.GL_LESS)
            GL.glDepthRange(0.0, 1.0)
            GL.glClearColor(*scene.bg_color)
            GL.glClear(GL.GL_COLOR_BUFFER_BIT | GL.GL_DEPTH_BUFFER_BIT)
            GL.glEnable(GL.GL_MULTISAMPLE)
            cams = []
            for node, (x, y, w, h) in self.views:
                pose = scene.get_pose(node)
                cams.append((np.linalg.inv(pose), node.camera.get_projection_matrix(width=w, height=h),
                             pose[:3, 3], (x, y, w, h)))
            GL.glEnable(GL.GL_SCISSOR_TEST)
            program = None
            lit = {}  # program -> texture units its lights (shadow maps) hold, bound in this pass
            same_lights = self._lights_fit(scene, flags)
            counts = _light_counts(self, scene, flags) if self.fixed_lights else None
            try:
                for node in self.order if self.order is not None else self._sorted_mesh_nodes(scene):
                    if not node.mesh.is_visible:
                        continue
                    pose = scene.get_pose(node)
                    for primitive in node.mesh.primitives:
                        program = self._lit_program(primitive, flags, counts)
                        program._bind()
                        if id(program) not in lit or not same_lights:
                            self._reset_active_textures()
                            self._bind_lighting(scene, program, node, flags)
                            lit[id(program)] = self._texture_alloc_idx
                        for V, P, cam_pos, region in cams:
                            GL.glViewport(*region)
                            GL.glScissor(*region)
                            program.set_uniform("V", V)
                            program.set_uniform("P", P)
                            program.set_uniform("cam_pos", cam_pos)
                            # the material's textures on the units after the shadow maps', view after
                            # view (from unit 0 they would replace the shadow maps in the next view)
                            self._texture_alloc_idx = lit[id(program)]
                            self._bind_and_draw_primitive(primitive=primitive, pose=pose, program=program,
                                                          flags=flags)
                        self._reset_active_textures()
                if program is not None:
                    program._unbind()
            finally:
                GL.glDisable(GL.GL_SCISSOR_TEST)
            GL.glFlush()
            return self._read_both(W, H)

        def _configure_main_framebuffer(self):
            """pyrender's framebuffers, the multisampled ones with ``samples`` samples per pixel
            (pyrender's 4 unless set; 0: no multisampling, each pixel shaded and covered once)."""
            fresh = self._main_fb is None or self._main_fb_dims != (self.viewport_width, self.viewport_height)
            super()._configure_main_framebuffer()
            if fresh and self.samples != 4:
                for rb, fmt in ((self._main_cb_ms, GL.GL_RGBA), (self._main_db_ms, GL.GL_DEPTH_COMPONENT24)):
                    GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, rb)
                    GL.glRenderbufferStorageMultisample(GL.GL_RENDERBUFFER, self.samples, fmt,
                                                        self.viewport_width, self.viewport_height)

        def _lights_fit(self, scene, flags) -> bool:
            """Every light is bound, whatever the node (pyrender sorts lights by their distance from
            the node only when there are more than its shaders hold): a program's light uniforms
            and shadow-map units, once bound in a pass, hold for all its primitives."""
            n_d, n_s, n_p = self._compute_max_n_lights(flags)
            return (len(scene.directional_light_nodes) <= n_d and len(scene.spot_light_nodes) <= n_s
                    and len(scene.point_light_nodes) <= n_p)

        def _get_primitive_program(self, primitive, flags, program_flags=ProgramFlags.NONE):
            return _fast_uniforms(super()._get_primitive_program(primitive, flags, program_flags))

        def delete(self):
            if self._lipgen_fixed_cache is not None:  # its programs, as pyrender frees its own
                self._lipgen_fixed_cache.clear()
            super().delete()

        def _lit_program(self, primitive, flags, counts):
            """pyrender's program for ``primitive``, or (``counts`` given) its fragment shader with
            the light loops' bounds fixed at compile time (:func:`fixed_light_shader`)."""
            program = self._get_primitive_program(primitive, flags, ProgramFlags.USE_MATERIAL)
            path = fixed_light_shader(program.fragment_shader) if counts is not None else None
            if path is None:
                return program
            if self._lipgen_fixed_cache is None:
                from pyrender.shader_program import ShaderProgramCache

                self._lipgen_fixed_cache = ShaderProgramCache()
            defines = dict(program.defines, **counts)
            fixed = self._lipgen_fixed_cache.get_program(vertex_shader=program.vertex_shader,
                                                         fragment_shader=path, defines=defines)
            if not fixed._in_context():
                fixed._add_to_context()
            return _fast_uniforms(fixed)

        def _read_both(self, W: int, H: int):
            GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, self._main_fb_ms)
            GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, self._main_fb)
            GL.glBlitFramebuffer(0, 0, W, H, 0, 0, W, H, GL.GL_COLOR_BUFFER_BIT, GL.GL_LINEAR)
            if self.want_depth:
                GL.glBlitFramebuffer(0, 0, W, H, 0, 0, W, H, GL.GL_DEPTH_BUFFER_BIT, GL.GL_NEAREST)
            GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, self._main_fb)
            GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 1)
            color = np.empty((H, W, 3), np.uint8)
            GL.glReadPixels(0, 0, W, H, GL.GL_RGB, GL.GL_UNSIGNED_BYTE, color)
            depth = None
            if self.want_depth:
                depth = np.empty((H, W), np.float32)
                GL.glReadPixels(0, 0, W, H, GL.GL_DEPTH_COMPONENT, GL.GL_FLOAT, depth)
            return color, depth

    return OnePassRenderer


_LOOPS = {"LIPGEN_N_DIRECTIONAL": "for (int i = 0; i < n_directional_lights; i++)",
          "LIPGEN_N_POINT": "for (int i = 0; i < n_point_lights; i++)",
          "LIPGEN_N_SPOT": "for (int i = 0; i < n_spot_lights; i++)"}


def fixed_light_shader(path: str) -> str | None:
    """Path of a copy of the fragment shader at ``path`` whose light loops run to compile-time
    bounds (``LIPGEN_N_DIRECTIONAL``, ``LIPGEN_N_POINT``, ``LIPGEN_N_SPOT``, given as defines with
    the counts pyrender binds) instead of to the ``n_*_lights`` uniforms; None unless the shader
    is pyrender's ``mesh.frag`` (or lipgen's shadow-filtered copy) with each loop exactly once.

    Written once per process to a temporary folder, removed at exit; written again if that folder
    has gone (e.g. removed by a forked child's exit).
    """
    out = _write_fixed_light_shader(path)
    if out is not None and not os.path.exists(out):
        _write_fixed_light_shader.cache_clear()
        out = _write_fixed_light_shader(path)
    return out


@functools.lru_cache(maxsize=8)
def _write_fixed_light_shader(path: str) -> str | None:
    if os.path.basename(path) != "mesh.frag" or not os.path.exists(path):
        return None
    with open(path) as fh:
        text = fh.read()
    for name, loop in _LOOPS.items():
        if text.count(loop) != 1:
            log.info("%s: the light loop %r is not there once; pyrender's own shader is kept", path, loop)
            return None
        text = text.replace(loop, loop.replace(loop.split("< ")[1].split(";")[0], name))
    folder = tempfile.mkdtemp(prefix="lipgen-lights-")
    atexit.register(shutil.rmtree, folder, True)
    tag = hashlib.sha1(path.encode()).hexdigest()[:10]  # pyrender's program cache keys by file name
    out = os.path.join(folder, f"lipgen_mesh_fixed_{tag}.frag")
    with open(out, "w") as fh:
        fh.write(text)
    return out


def _light_counts(renderer, scene, flags) -> dict:
    """The light counts pyrender's ``_bind_lighting`` binds (its ``n_*_lights`` uniforms), as defines."""
    n_d, n_s, n_p = renderer._compute_max_n_lights(flags)
    return {"LIPGEN_N_DIRECTIONAL": min(len(scene.directional_light_nodes), n_d),
            "LIPGEN_N_SPOT": min(len(scene.spot_light_nodes), n_s),
            "LIPGEN_N_POINT": min(len(scene.point_light_nodes), n_p)}


def _set_uniform(self, name, value, unsigned=False):
    """pyrender 0.1.45's ``ShaderProgram.set_uniform`` (the same GL calls, errors ignored as there),
    with each uniform's location looked up once per linked program instead of at every call."""
    from OpenGL import GL

    try:
        key = (self._program_id, name)
        loc = self._lipgen_locations.get(key)
        if loc is None:
            loc = self._lipgen_locations[key] = GL.glGetUniformLocation(self._program_id, name)
        if loc == -1:
            raise ValueError(f"Invalid shader variable: {name}")
        if isinstance(value, np.ndarray):
            if value.ndim == 1:
                if value.dtype.kind == "u" or unsigned:
                    dtype, value = "u", value.astype(np.uint32)
                elif value.dtype.kind == "i":
                    dtype, value = "i", value.astype(np.int32)
                else:
                    dtype, value = "f", value.astype(np.float32)
                self._FUNC_MAP[(value.shape[0], dtype)](loc, 1, value)
            else:
                self._FUNC_MAP[(value.shape[0], value.shape[1])](loc, 1, GL.GL_TRUE, value)
        elif isinstance(value, float):
            GL.glUniform1f(loc, value)
        elif isinstance(value, int):
            (GL.glUniform1ui if unsigned else GL.glUniform1i)(loc, value)
        else:
            raise ValueError("Invalid data type")
    except Exception:  # noqa: BLE001 - pyrender's own behaviour: a uniform the shader lacks is skipped
        pass


def _fast_uniforms(program):
    """``program`` with :func:`_set_uniform` as its ``set_uniform`` (once per program object)."""
    if "_lipgen_locations" not in program.__dict__:
        program._lipgen_locations = {}
        program.set_uniform = _set_uniform.__get__(program)
    return program


def install(offscreen, pr) -> bool:
    """Give ``offscreen`` (a ``pyrender.OffscreenRenderer``) the one-pass renderer.

    Returns False, changing nothing, when its platform draws without framebuffer objects or
    pyrender is not the release this was written against (:data:`lipgen.rig._pyscene.TESTED_PYRENDER`).
    """
    from lipgen.rig._pyscene import internals_known

    if not internals_known(pr) or not offscreen._platform.supports_framebuffers():
        return False
    offscreen._renderer.__class__ = _one_pass_class(pr)  # adds methods only; no state to convert
    return True


def _linear_depth(d: np.ndarray, znear: float, zfar: float) -> np.ndarray:
    """Window depth (0-1) to distance along the camera axis, 0 where nothing was drawn (the same
    float32 arithmetic as pyrender's read-back)."""
    inf = d == 1.0
    d = 2.0 * d - 1.0
    ok = ~inf
    d[ok] = (2.0 * znear * zfar) / (zfar + znear - d[ok] * (zfar - znear))
    d[inf] = 0.0
    return d


def _draw_order(renderer, scene, nodes) -> list | None:
    """The mesh nodes in the order every camera of ``nodes`` draws them, or None if they differ."""
    orders = []
    for node in nodes:
        scene.main_camera_node = node
        orders.append(renderer._sorted_mesh_nodes(scene))
    first = [id(n) for n in orders[0]]
    return orders[0] if all([id(n) for n in o] == first for o in orders[1:]) else None


def render_side_by_side(offscreen, scene, views, flags, depth: bool = False):
    """Draw the views side by side in one forward pass and read the framebuffer back once.

    Parameters
    ----------
    offscreen : pyrender.OffscreenRenderer
        After :func:`install` returned True.
    scene : pyrender.Scene
    views : list of (node, width, height)
        Camera nodes (pyrender ``IntrinsicsCamera`` s) and their image sizes, left to right.
    flags : int
        ``pyrender.RenderFlags`` of a colour render (OFFSCREEN is added).
    depth : bool
        Also read the depth buffer (linear, mm; 0 where nothing was drawn).

    Returns
    -------
    list of (color (h, w, 3) uint8, depth (h, w) float32 or None), or None
        One per view, rows top-down; None when the views would draw the meshes in different
        orders (the caller then renders them one by one).
    """
    from pyrender.constants import RenderFlags

    r = offscreen._renderer
    order = _draw_order(r, scene, [node for node, _, _ in views])
    if order is None:
        return None
    H = max(int(h) for _, _, h in views)
    regions, x = [], 0
    for node, w, h in views:
        regions.append((node, (x, H - int(h), int(w), int(h))))  # GL rows count from the bottom
        x += int(w)
    offscreen._platform.make_current()
    r.point_size = offscreen.point_size
    r.views, r.want_depth, r.order = regions, bool(depth), order
    try:
        color, z = r.render(scene, flags | RenderFlags.OFFSCREEN)
    finally:
        r.views, r.want_depth, r.order = None, False, None
        offscreen._platform.make_uncurrent()
    color = color[::-1]
    z = None if z is None else z[::-1]
    out = []
    for node, (x, _, w, h) in regions:
        zi = None
        if z is not None:
            zi = _linear_depth(np.ascontiguousarray(z[:h, x:x + w]), node.camera.znear, node.camera.zfar)
        out.append((color[:h, x:x + w], zi))
    return out
