"""pyrender's shadow-map filter with the same result in 4 texture gathers instead of 36 reads.

pyrender's fragment shader softens shadow edges by percentage-closer filtering (PCF): for each
of 3 x 3 offsets one texel apart it compares the fragment's depth with the 2 x 2 shadow-map texels
around that point and interpolates the four answers bilinearly, with the same fractions
``f = fract(uv * size + 0.5)`` at every offset. That is 36 texture reads per fragment and light,
most of them of the same 16 texels: the offsets overlap. Summed out, the filter is a separable
weighting of the 4 x 4 texels ``k - 1 .. k + 2`` (``k = floor(uv * size + 0.5)``) by
``(1 - f, 1, 1, f)`` in x times the same in y, over 9. :data:`SHADOW_CALC` reads the 16 texels
as four 2 x 2 ``textureGather`` s (OpenGL 4.0, or ARB_texture_gather; wrapped as the shadow
texture's REPEAT sampler wraps) and weights them so; :data:`SHADOW_CALC_FETCH` reads them one by
one (``texelFetch``) where gathers are missing. The arithmetic is the same sum in another order:
on the hard preset's frames the images are byte-identical (``tests/test_shadowmap.py``), and a
shadowed render of the hard scene costs about 0.42 of the CPU with the gathers, 0.53 with 16
reads (llvmpipe, where every texture read is done in software; ``lipgen bench --suite presets``).

:func:`install` gives an offscreen renderer a shader cache whose ``mesh.frag`` is pyrender's with
``shadow_calc`` replaced. It changes nothing (and says so, returning False) unless pyrender's
filter is the exact text this was derived from (pyrender 0.1.45) and the shadow maps have a
power-of-two size.
"""

from __future__ import annotations

import atexit
import functools
import hashlib
import logging
import os
import shutil
import tempfile

__all__ = ["install", "patched_mesh_shader", "SHADOW_CALC", "SHADOW_CALC_FETCH"]

log = logging.getLogger(__name__)

_PCF_SHA256 = "1afa7eb7b9e2fea6a3fe659029c1e37f42c4b4f01749b01374fbca7ab018c32d"
"""sha256 of pyrender's ``texture2DCompare`` .. ``shadow_calc`` text in ``mesh.frag`` (0.1.45)."""

_HEAD = """float shadow_calc(mat4 light_matrix, sampler2D shadow_map, float nl)
{
    // Compute light texture UV coords
    vec4 proj_coords = vec4(light_matrix * vec4(frag_position.xyz, 1.0));
    vec3 light_coords = proj_coords.xyz / proj_coords.w;
    light_coords = light_coords * 0.5 + 0.5;
    float current_depth = light_coords.z;
    float bias = max(0.001 * (1.0 - nl), 0.0001) / proj_coords.w;
    float compare = (current_depth - bias);
    // pyrender's 3 x 3 bilinear PCF, summed out: 4 x 4 texels, weights (1 - f, 1, 1, f) per axis, / 9
"""
_TAIL = """    if (light_coords.z > 1.0) {
        shadow = 0.0;
    }
    return shadow;
}

"""

SHADOW_CALC_FETCH = _HEAD + """    ivec2 size = textureSize(shadow_map, 0);
    vec2 p = light_coords.xy * vec2(size) + 0.5;
    vec2 f = fract(p);
    ivec2 k = ivec2(floor(p));
    ivec2 m = size - 1;  // power-of-two sizes: & m wraps as GL_REPEAT does
    vec4 wx = vec4(1.0 - f.x, 1.0, 1.0, f.x);
    vec4 wy = vec4(1.0 - f.y, 1.0, 1.0, f.y);
    float shadow = 0.0;
    for (int j = 0; j < 4; j++) {
        int y = (k.y + j - 1) & m.y;
        vec4 c;
        for (int i = 0; i < 4; i++) {
            c[i] = compare > texelFetch(shadow_map, ivec2((k.x + i - 1) & m.x, y), 0).r ? 1.0 : 0.0;
        }
        shadow += wy[j] * dot(wx, c);
    }
    shadow = shadow / 9.0;
""" + _TAIL
"""GLSL replacing pyrender's ``texture2DCompare`` .. ``shadow_calc``: 16 ``texelFetch`` reads."""

SHADOW_CALC = _HEAD + """    vec2 size = vec2(textureSize(shadow_map, 0));
    vec2 p = light_coords.xy * size + 0.5;
    vec2 f = fract(p);
    vec2 k = floor(p);
    // a gather at texel corner k reads texels k - 1 and k per axis, in the order
    // x = (i0, j1), y = (i1, j1), z = (i1, j0), w = (i0, j0)
    vec4 c00 = vec4(greaterThan(vec4(compare), textureGather(shadow_map, k / size)));
    vec4 c10 = vec4(greaterThan(vec4(compare), textureGather(shadow_map, (k + vec2(2.0, 0.0)) / size)));
    vec4 c01 = vec4(greaterThan(vec4(compare), textureGather(shadow_map, (k + vec2(0.0, 2.0)) / size)));
    vec4 c11 = vec4(greaterThan(vec4(compare), textureGather(shadow_map, (k + vec2(2.0, 2.0)) / size)));
    float ax = 1.0 - f.x, bx = f.x;
    float row0 = ax * c00.w + c00.z + c10.w + bx * c10.z;
    float row1 = ax * c00.x + c00.y + c10.x + bx * c10.y;
    float row2 = ax * c01.w + c01.z + c11.w + bx * c11.z;
    float row3 = ax * c01.x + c01.y + c11.x + bx * c11.y;
    float shadow = ((1.0 - f.y) * row0 + row1 + row2 + f.y * row3) / 9.0;
""" + _TAIL
"""GLSL replacing pyrender's ``texture2DCompare`` .. ``shadow_calc``: four ``textureGather`` s."""

_GATHER_EXTENSION = "#extension GL_ARB_texture_gather : require\n"


def _segment(src: str) -> tuple[int, int]:
    a = src.index("float texture2DCompare(")
    return a, src.index("///", src.index("float shadow_calc("))


@functools.lru_cache(maxsize=2)
def patched_mesh_shader(gather: bool = True) -> str | None:
    """Path of pyrender's ``mesh.frag`` with :data:`SHADOW_CALC` (``gather``) or
    :data:`SHADOW_CALC_FETCH` (written once per process to a temporary folder, removed at exit);
    None when pyrender's shader is not the one it replaces."""
    import pyrender
    from pyrender.constants import SHADOW_TEX_SZ

    if SHADOW_TEX_SZ & (SHADOW_TEX_SZ - 1):
        log.info("pyrender's shadow maps are %d texels, not a power of two: its own PCF is kept",
                 SHADOW_TEX_SZ)
        return None
    path = os.path.join(os.path.dirname(pyrender.__file__), "shaders", "mesh.frag")
    with open(path) as fh:
        src = fh.read()
    try:
        a, b = _segment(src)
    except ValueError:
        a = b = 0
    if hashlib.sha256(src[a:b].encode()).hexdigest() != _PCF_SHA256:
        log.info("pyrender's shadow filter is not the one lipgen's replaces (%s): its own is kept", path)
        return None
    folder = tempfile.mkdtemp(prefix="lipgen-shaders-")
    atexit.register(shutil.rmtree, folder, True)
    out = os.path.join(folder, "mesh.frag")
    text = src[:a] + (SHADOW_CALC if gather else SHADOW_CALC_FETCH) + src[b:]
    if gather:  # the extension line goes right after #version
        head, _, rest = text.partition("\n")
        text = head + "\n" + _GATHER_EXTENSION + rest
    with open(out, "w") as fh:
        fh.write(text)
    return out


def _has_gather(offscreen) -> bool:
    """The offscreen renderer's OpenGL has textureGather (4.0 core, or ARB_texture_gather)."""
    from OpenGL import GL

    offscreen._platform.make_current()
    try:
        n = int(GL.glGetIntegerv(GL.GL_NUM_EXTENSIONS))
        names = {GL.glGetStringi(GL.GL_EXTENSIONS, i) for i in range(n)}
    finally:
        offscreen._platform.make_uncurrent()
    return b"GL_ARB_texture_gather" in names


def install(offscreen, gather: bool | None = None) -> bool:
    """Make ``offscreen`` (a ``pyrender.OffscreenRenderer``) draw meshes with the gathered (or,
    without gathers, 16-read) shadow filter; False (nothing changed) when pyrender's shader is not
    the expected one. ``gather`` forces one or the other (None: gathers where OpenGL has them)."""
    from pyrender.shader_program import ShaderProgramCache

    gather = _has_gather(offscreen) if gather is None else bool(gather)
    shader = patched_mesh_shader(gather)
    if shader is not None and not os.path.exists(shader):  # e.g. removed by a forked child's exit
        patched_mesh_shader.cache_clear()
        shader = patched_mesh_shader(gather)
    if shader is None:
        return False

    class Cache(ShaderProgramCache):
        def get_program(self, vertex_shader, fragment_shader, geometry_shader=None, defines=None):
            if fragment_shader == "mesh.frag":  # an absolute path: os.path.join keeps it as it is
                fragment_shader = shader
            return super().get_program(vertex_shader, fragment_shader, geometry_shader, defines)

    renderer = offscreen._renderer
    renderer._program_cache.clear()
    renderer._program_cache = Cache()
    return True
