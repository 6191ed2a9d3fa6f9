"""A :class:`~lipgen.rig.scene.Scene` as pyrender objects: meshes, lights, draw order, label colours.

Used by :mod:`lipgen.rig.render` (which holds the OpenGL context); pyrender is passed in, never
imported here.
"""

from __future__ import annotations

import hashlib

import numpy as np

from lipgen.rig.scene import MeshItem, srgb_to_linear

__all__: list[str] = []


TESTED_PYRENDER = "0.1.45"
"""The pyrender release whose internals the in-place vertex upload (here), the one-pass renderer
(:mod:`lipgen.rig._onepass`) and the shadow filter (:mod:`lipgen.rig._shadowmap`, which also checks
the shader's hash) were written against; with another release they stand aside."""


def internals_known(pr) -> bool:
    """True when ``pr`` (the pyrender module) is :data:`TESTED_PYRENDER`."""
    return getattr(pr, "__version__", None) == TESTED_PYRENDER


def delete_offscreen(pr, offscreen) -> None:
    """Free ``offscreen`` (a ``pyrender.OffscreenRenderer``) as its ``delete()`` does, without the full
    garbage collection that ends it.

    That ``gc.collect()`` walks the whole heap of the calling process: 0.35 s of CPU per renderer in a
    pytest worker, more in a larger process, and nothing to collect that holds OpenGL objects: the
    renderer's ``delete()`` has freed them, and the finalisers that pyrender's renderer and platform
    run when the collector takes them later find nothing left to free (every handle is None). With
    another release (:func:`internals_known`) its own ``delete()`` runs.
    """
    if not internals_known(pr):
        offscreen.delete()
        return
    offscreen._platform.make_current()
    offscreen._renderer.delete()
    offscreen._platform.delete_context()
    offscreen._renderer = offscreen._platform = None


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


def _fingerprint(item: MeshItem) -> tuple[str, str]:
    """``(layout, geometry)`` hashes of ``item``: its faces, materials and uv, and its vertices and
    normals. An item whose layout is unchanged keeps its meshes; only their vertex data change."""
    keys = []
    for arrays in ((item.faces, item.face_material, item.uv), (item.vertices, item.normals)):
        h = hashlib.blake2b(digest_size=16)
        for a in arrays:
            if a is not None:
                h.update(np.ascontiguousarray(a).tobytes())
        keys.append(h)
    keys[0].update(repr([m.key for m in item.materials]).encode())
    return keys[0].hexdigest(), keys[1].hexdigest()


_ATTRIBUTES = ("positions", "normals", "tangents", "texcoord_0", "texcoord_1", "color_0")  # pyrender's order


def _vertex_data(prim) -> np.ndarray:
    """The interleaved float32 vertex buffer pyrender 0.1.45 uploads for ``prim``
    (``Primitive._add_to_context``): its attributes side by side, in ``_ATTRIBUTES`` order."""
    parts = [a for a in (getattr(prim, name) for name in _ATTRIBUTES) if a is not None]
    return np.ascontiguousarray(np.hstack(parts).flatten().astype(np.float32))


def _set_vertices(mesh, item: MeshItem) -> bool:
    """Give ``mesh`` (made by :func:`_pyrender_mesh` from an item of the same layout) ``item``'s
    vertices and normals. Returns True when its vertex buffer on the GPU must be written again."""
    prim = mesh.primitives[0]
    used = mesh._lipgen_used
    prim.positions = item.vertices[used].astype(np.float32)
    prim.normals = item.normals[used].astype(np.float32)
    mesh._bounds = None  # pyrender caches them (shadow cameras and the scene scale use them)
    return prim._vaid is not None


def _upload_vertices(prims) -> None:
    """Write each primitive's vertex data into its vertex buffer in place (the GL context is current)."""
    from OpenGL import GL

    for prim in prims:
        data = _vertex_data(prim)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, prim._buffers[0])
        GL.glBufferSubData(GL.GL_ARRAY_BUFFER, 0, data.nbytes, data)
    GL.glBindBuffer(GL.GL_ARRAY_BUFFER, 0)


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
    mesh = pr.Mesh([prim], name=f"{item.name}:{mat.name}")
    mesh._lipgen_used = used  # the item's vertices this mesh holds, in order (see _set_vertices)
    return mesh


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
