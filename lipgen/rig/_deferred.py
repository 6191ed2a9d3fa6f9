"""The one-pass raw frame shaded once per covered pixel: a G-buffer, then pyrender's own shading.

Why: on Mesa's llvmpipe a fragment shader runs on blocks of 8 pixels (two 2 x 2 quads), the whole
block whenever any of its pixels is covered. The subject's triangles are small (tens of pixels),
so most blocks are partly covered and the forward pass paid pyrender's lighting for about three
times the pixels it drew (measured: a full-screen quad shades 307,200 pixels for about 40 ms of CPU;
the raw frame's 122,000 covered pixels cost 51 ms of shading). Here the geometry pass writes, per
sample, only what pyrender's fragment shader reads (the interpolated position and normal, the
material's slot and the base colour, its texture applied), and pyrender's ``mesh.frag`` then
runs once per covered pixel in full-screen passes, where every block is full.

The same pixels: the geometry pass is pyrender's (same vertex shader, draw order, depth test,
culling and multisampling), and the shading pass is pyrender's ``mesh.frag`` text (with lipgen's
shadow filter when installed) whose ``main`` reads the stored values instead of its inputs. A
pixel whose covered samples hold identical values (one triangle) is shaded once and written to
those samples, as the forward pass does; a pixel whose samples differ (an edge between triangles)
is marked in the stencil and shaded per sample. Background samples keep the clear colour. The
colour buffer is then resolved and read as before. Scenes with blending, textures other than
the base colour, or a material pyrender shades otherwise, and depth read-backs, keep the forward
pass (:func:`supported`).
"""

from __future__ import annotations

import atexit
import functools
import os
import re
import shutil
import tempfile

import numpy as np

__all__ = ["Deferred", "supported", "shader_texts"]

_MAX_MATERIALS = 64

_GBUF_MAIN = """
layout(location = 0) out vec4 g_position;
layout(location = 1) out vec4 g_normal;
layout(location = 2) out vec4 g_base;
uniform float lipgen_slot;
void main()
{
    vec4 base_color = material.base_color_factor;
#ifdef HAS_BASE_COLOR_TEX
    base_color = base_color * srgb_to_linear(texture(material.base_color_texture, uv_0));
#endif
    g_position = vec4(frag_position, lipgen_slot);
    g_normal = vec4(frag_normal, 1.0);
    g_base = base_color;
}
"""

_SHADE_HEAD = """
uniform Material lipgen_materials[LIPGEN_N_MATERIALS];
uniform sampler2DMS lipgen_g_position;
uniform sampler2DMS lipgen_g_normal;
uniform sampler2DMS lipgen_g_base;
uniform int lipgen_sample;
vec3 frag_position;
vec3 frag_normal;
Material material;
"""

_SHADE_MAIN = """
void main()
{
    ivec2 px = ivec2(gl_FragCoord.xy);
#ifdef LIPGEN_PER_SAMPLE
    int s = lipgen_sample;  // the only sample this draw writes (glSampleMaski)
#else
    int s = 0;  // the first covered sample (all covered samples hold the same values here)
    for (int k = 3; k > 0; k--) {
        if (texelFetch(lipgen_g_normal, px, k).w > 0.5) s = k;
    }
    if (texelFetch(lipgen_g_normal, px, 0).w > 0.5) s = 0;
#endif
    vec4 p = texelFetch(lipgen_g_position, px, s);
    frag_position = p.xyz;
    frag_normal = texelFetch(lipgen_g_normal, px, s).xyz;
    material = lipgen_materials[int(p.w)];
    material.base_color_factor = texelFetch(lipgen_g_base, px, s);
    lipgen_shade();
}
"""

_MARK_FRAG = """#version 330 core
uniform sampler2DMS lipgen_g_position;
uniform sampler2DMS lipgen_g_normal;
uniform sampler2DMS lipgen_g_base;
out vec4 frag_color;
void main()
{
    ivec2 px = ivec2(gl_FragCoord.xy);
    bool first = true, same = true;
    vec4 p0, n0, b0;
    for (int k = 0; k < 4; k++) {
        vec4 n = texelFetch(lipgen_g_normal, px, k);
        if (n.w < 0.5) continue;
        vec4 p = texelFetch(lipgen_g_position, px, k);
        vec4 b = texelFetch(lipgen_g_base, px, k);
        if (first) { p0 = p; n0 = n; b0 = b; first = false; }
        else if (p != p0 || n != n0 || b != b0) same = false;
    }
    if (same) discard;
    frag_color = vec4(1.0);
}
"""

_QUAD_VERT = """#version 330 core
void main()
{
    vec2 c = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
    gl_Position = vec4(c, 0.0, 1.0);
}
"""


def _split(src: str) -> tuple[str, str, str]:
    """pyrender's ``mesh.frag``: (head before its inputs, declarations to the main, main)."""
    a = src.index("in vec3 frag_position;")
    m = src.index("void main()")
    return src[:a], src[a:m], src[m:]


def shader_texts(mesh_frag: str) -> dict[str, str]:
    """The geometry, shading (per pixel and per sample), marking and quad shaders made from the
    text of pyrender's ``mesh.frag`` (perhaps with lipgen's shadow filter)."""
    head, decl, main = _split(mesh_frag)
    decl_out = decl.replace("out vec4 frag_color;", "")
    gbuf = head + decl_out + _GBUF_MAIN
    shade_decl = re.sub(r"in vec3 frag_position;\n", "", decl)
    shade_decl = re.sub(r"#ifdef NORMAL_LOC\nin vec3 frag_normal;\n#endif\n", "", shade_decl)
    if "in vec3 frag_" in shade_decl:
        raise ValueError("mesh.frag's inputs are not the ones the shading pass replaces")
    shade_head = head.replace("uniform Material material;", "")
    if shade_head == head:
        raise ValueError("mesh.frag has no 'uniform Material material;'")
    body = main.replace("void main()", "void lipgen_shade()", 1)
    shade = shade_head + _SHADE_HEAD + shade_decl + body + _SHADE_MAIN
    return {"lipgen_gbuf.frag": gbuf, "lipgen_shade.frag": shade,
            "lipgen_mark.frag": _MARK_FRAG, "lipgen_quad.vert": _QUAD_VERT}


@functools.lru_cache(maxsize=4)
def _shader_folder(mesh_frag_path: str) -> str:
    with open(mesh_frag_path) as fh:
        texts = shader_texts(fh.read())
    folder = tempfile.mkdtemp(prefix="lipgen-deferred-")
    atexit.register(shutil.rmtree, folder, True)
    for name, text in texts.items():
        with open(os.path.join(folder, name), "w") as fh:
            fh.write(text)
    return folder


def supported(renderer, scene, order, flags) -> bool:
    """True when every visible primitive of ``order`` is drawn the way the deferred pass
    reproduces: opaque metallic-roughness material, normals, no texture but the base colour."""
    from pyrender.constants import BufFlags, TexFlags
    from pyrender.material import MetallicRoughnessMaterial

    n = 0
    for node in order:
        if not node.mesh.is_visible:
            continue
        for prim in node.mesh.primitives:
            mat = prim.material
            n += 1
            if (not isinstance(mat, MetallicRoughnessMaterial) or mat.alphaMode == "BLEND" or mat.wireframe
                    or mat.tex_flags & ~TexFlags.BASE_COLOR or not prim.buf_flags & BufFlags.NORMAL
                    or prim.buf_flags & (BufFlags.COLOR_0 | BufFlags.TANGENT | BufFlags.JOINTS_0)
                    or prim.mode != 4 or (prim.poses is not None and len(prim.poses) > 1)):
                return False
    return 0 < n <= _MAX_MATERIALS


class Deferred:
    """The framebuffers and programs of the deferred pass, for one renderer (its GL context)."""

    def __init__(self, mesh_frag_path: str) -> None:
        from pyrender.shader_program import ShaderProgramCache

        import pyrender

        self.folder = _shader_folder(mesh_frag_path)
        self.mesh_vert = os.path.join(os.path.dirname(pyrender.__file__), "shaders", "mesh.vert")
        self.cache = ShaderProgramCache(self.folder)
        self.size = None
        self.ids = None
        self.vao = None

    def _program(self, vert, frag, defines):
        p = self.cache.get_program(vertex_shader=vert, fragment_shader=frag, defines=defines)
        if not p._in_context():
            p._add_to_context()
        return p

    def framebuffers(self, W: int, H: int, samples: int) -> None:
        """Make (or keep) the G-buffer and colour framebuffers for a W x H frame."""
        from OpenGL import GL

        if self.size == (W, H, samples):
            return
        self.delete()
        tex = GL.glGenTextures(4)
        for t, fmt in zip(tex, (GL.GL_RGBA32F, GL.GL_RGBA32F, GL.GL_RGBA32F, GL.GL_DEPTH24_STENCIL8), strict=True):
            GL.glBindTexture(GL.GL_TEXTURE_2D_MULTISAMPLE, t)
            GL.glTexImage2DMultisample(GL.GL_TEXTURE_2D_MULTISAMPLE, samples, fmt, W, H, GL.GL_TRUE)
        GL.glBindTexture(GL.GL_TEXTURE_2D_MULTISAMPLE, 0)
        rb = GL.glGenRenderbuffers(1)
        GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, rb)
        GL.glRenderbufferStorageMultisample(GL.GL_RENDERBUFFER, samples, GL.GL_RGBA, W, H)
        fb_g, fb_c = GL.glGenFramebuffers(2)
        GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, fb_g)
        for k in range(3):
            GL.glFramebufferTexture2D(GL.GL_DRAW_FRAMEBUFFER, GL.GL_COLOR_ATTACHMENT0 + k,
                                      GL.GL_TEXTURE_2D_MULTISAMPLE, tex[k], 0)
        GL.glFramebufferTexture2D(GL.GL_DRAW_FRAMEBUFFER, GL.GL_DEPTH_STENCIL_ATTACHMENT,
                                  GL.GL_TEXTURE_2D_MULTISAMPLE, tex[3], 0)
        ok_g = GL.glCheckFramebufferStatus(GL.GL_DRAW_FRAMEBUFFER)
        GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, fb_c)
        GL.glFramebufferRenderbuffer(GL.GL_DRAW_FRAMEBUFFER, GL.GL_COLOR_ATTACHMENT0, GL.GL_RENDERBUFFER, rb)
        GL.glFramebufferTexture2D(GL.GL_DRAW_FRAMEBUFFER, GL.GL_DEPTH_STENCIL_ATTACHMENT,
                                  GL.GL_TEXTURE_2D_MULTISAMPLE, tex[3], 0)
        ok_c = GL.glCheckFramebufferStatus(GL.GL_DRAW_FRAMEBUFFER)
        self.ids = {"tex": [int(t) for t in tex], "rb": int(rb), "fb_g": int(fb_g), "fb_c": int(fb_c)}
        self.size = (W, H, samples)
        if self.vao is None:
            self.vao = int(GL.glGenVertexArrays(1))
        if ok_g != GL.GL_FRAMEBUFFER_COMPLETE or ok_c != GL.GL_FRAMEBUFFER_COMPLETE:
            raise RuntimeError(f"deferred framebuffers incomplete: {ok_g:#x} {ok_c:#x}")

    def delete(self) -> None:
        """Release the framebuffers (the GL context is current)."""
        from OpenGL import GL

        if self.ids is not None:
            GL.glDeleteFramebuffers(2, [self.ids["fb_g"], self.ids["fb_c"]])
            GL.glDeleteRenderbuffers(1, [self.ids["rb"]])
            GL.glDeleteTextures(self.ids["tex"])
        self.ids, self.size = None, None

    def draw(self, r, scene, flags, order, cams, W: int, H: int) -> None:
        """Draw the frame into the colour framebuffer ``ids['fb_c']`` (multisampled, unresolved).

        ``r`` is the one-pass renderer, ``cams`` its per-view (V, P, cam_pos, region)."""
        from OpenGL import GL
        from pyrender.constants import ProgramFlags

        ids = self.ids
        # ---- geometry: pyrender's draw order and state; stencil bit 0 marks covered samples
        GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, ids["fb_g"])
        GL.glDrawBuffers(3, [GL.GL_COLOR_ATTACHMENT0, GL.GL_COLOR_ATTACHMENT1, GL.GL_COLOR_ATTACHMENT2])
        GL.glViewport(0, 0, W, H)
        GL.glDisable(GL.GL_SCISSOR_TEST)
        GL.glEnable(GL.GL_DEPTH_TEST)
        GL.glDepthMask(GL.GL_TRUE)
        GL.glDepthFunc(GL.GL_LESS)
        GL.glDepthRange(0.0, 1.0)
        GL.glStencilMask(0xFF)
        GL.glClearBufferfv(GL.GL_COLOR, 1, np.zeros(4, np.float32))
        GL.glClearBufferfi(GL.GL_DEPTH_STENCIL, 0, 1.0, 0)
        GL.glEnable(GL.GL_MULTISAMPLE)
        GL.glEnable(GL.GL_STENCIL_TEST)
        GL.glStencilFunc(GL.GL_ALWAYS, 1, 0xFF)
        GL.glStencilOp(GL.GL_KEEP, GL.GL_KEEP, GL.GL_REPLACE)
        GL.glEnable(GL.GL_SCISSOR_TEST)
        materials, slots = [], {}
        shade_defines = None
        for node in order:
            if not node.mesh.is_visible:
                continue
            pose = scene.get_pose(node)
            for prim in node.mesh.primitives:
                mesh_prog = r._get_primitive_program(prim, flags, ProgramFlags.USE_MATERIAL)
                defines = dict(mesh_prog.defines)
                if shade_defines is None:
                    shade_defines = {k: v for k, v in defines.items()
                                     if not k.startswith(("HAS_", "TEXCOORD_"))}
                prog = _fast(self._program(self.mesh_vert, "lipgen_gbuf.frag", defines))
                prog._bind()
                mat = prim.material
                slot = slots.setdefault(id(mat), len(slots))
                if slot == len(materials):
                    materials.append(mat)
                prog.set_uniform("lipgen_slot", float(slot))
                for V, P, _, region in cams:
                    GL.glViewport(*region)
                    GL.glScissor(*region)
                    prog.set_uniform("V", V)
                    prog.set_uniform("P", P)
                    r._reset_active_textures()
                    r._bind_and_draw_primitive(primitive=prim, pose=pose, program=prog, flags=flags)
                r._reset_active_textures()
        GL.glDisable(GL.GL_BLEND)
        GL.glDisable(GL.GL_CULL_FACE)
        GL.glDisable(GL.GL_DEPTH_TEST)
        GL.glDepthMask(GL.GL_FALSE)
        # ---- colour framebuffer: the clear colour; mark pixels whose covered samples differ (bit 1)
        GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, ids["fb_c"])
        GL.glDrawBuffers(1, [GL.GL_COLOR_ATTACHMENT0])
        GL.glViewport(0, 0, W, H)
        GL.glScissor(0, 0, W, H)
        GL.glClearColor(*scene.bg_color)
        GL.glClear(GL.GL_COLOR_BUFFER_BIT)
        mark = _fast(self._program("lipgen_quad.vert", "lipgen_mark.frag", {}))
        mark._bind()
        self._bind_gbuffer(mark, 0)
        GL.glColorMask(GL.GL_FALSE, GL.GL_FALSE, GL.GL_FALSE, GL.GL_FALSE)
        GL.glStencilFunc(GL.GL_EQUAL, 3, 0x01)
        GL.glStencilOp(GL.GL_KEEP, GL.GL_KEEP, GL.GL_REPLACE)
        GL.glStencilMask(0x02)
        GL.glBindVertexArray(self.vao)  # after the programs are made (making one unbinds it)
        GL.glDrawArrays(GL.GL_TRIANGLE_STRIP, 0, 4)
        GL.glColorMask(GL.GL_TRUE, GL.GL_TRUE, GL.GL_TRUE, GL.GL_TRUE)
        GL.glStencilMask(0x00)
        GL.glStencilOp(GL.GL_KEEP, GL.GL_KEEP, GL.GL_KEEP)
        # ---- shading: once per pixel where the samples agree, per sample where they differ
        shade_defines = dict(shade_defines, LIPGEN_N_MATERIALS=len(materials))
        for ref in (1, 3):  # pyrender's loader sets #ifdef from the defines given, not from #define
            defines = dict(shade_defines, LIPGEN_PER_SAMPLE=1) if ref == 3 else shade_defines
            prog = _fast(self._program("lipgen_quad.vert", "lipgen_shade.frag", defines))
            prog._bind()
            r._reset_active_textures()
            r._bind_lighting(scene, prog, order[0], flags)
            self._bind_gbuffer(prog, r._texture_alloc_idx)
            for k, mat in enumerate(materials):
                b = f"lipgen_materials[{k}]."
                prog.set_uniform(b + "emissive_factor", mat.emissiveFactor)
                prog.set_uniform(b + "base_color_factor", mat.baseColorFactor)
                prog.set_uniform(b + "metallic_factor", mat.metallicFactor)
                prog.set_uniform(b + "roughness_factor", mat.roughnessFactor)
            GL.glStencilFunc(GL.GL_EQUAL, ref, 0x03)
            samples = range(self.size[2]) if ref == 3 else [None]
            for _, _, cam_pos, region in cams:
                GL.glViewport(*region)
                GL.glScissor(*region)
                prog.set_uniform("cam_pos", cam_pos)
                GL.glBindVertexArray(self.vao)
                for k in samples:  # where samples differ: one draw per sample, writing only it
                    if k is not None:
                        GL.glEnable(GL.GL_SAMPLE_MASK)
                        GL.glSampleMaski(0, 1 << k)
                        prog.set_uniform("lipgen_sample", k)
                    GL.glDrawArrays(GL.GL_TRIANGLE_STRIP, 0, 4)
            GL.glDisable(GL.GL_SAMPLE_MASK)
        r._reset_active_textures()
        GL.glBindVertexArray(0)
        GL.glUseProgram(0)
        GL.glDisable(GL.GL_STENCIL_TEST)
        GL.glDisable(GL.GL_SCISSOR_TEST)  # the resolve (a blit) is scissored too
        GL.glStencilMask(0xFF)
        GL.glDepthMask(GL.GL_TRUE)
        GL.glEnable(GL.GL_DEPTH_TEST)
        GL.glActiveTexture(GL.GL_TEXTURE0)

    def _bind_gbuffer(self, prog, unit: int) -> None:
        from OpenGL import GL

        for k, name in enumerate(("lipgen_g_position", "lipgen_g_normal", "lipgen_g_base")):
            GL.glActiveTexture(GL.GL_TEXTURE0 + unit + k)
            GL.glBindTexture(GL.GL_TEXTURE_2D_MULTISAMPLE, self.ids["tex"][k])
            prog.set_uniform(name, unit + k)


def _fast(program):
    from lipgen.rig._onepass import _fast_uniforms

    return _fast_uniforms(program)
