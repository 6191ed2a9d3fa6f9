"""Blender data for :mod:`lipgen.rig.cycles`: meshes, images, the world and Principled materials.

Helpers that turn the renderer-independent scene records into Blender data blocks; ``bpy`` is
passed in by the caller (the only importer of bpy in the rig stage is :mod:`lipgen.rig.cycles`).
"""

from __future__ import annotations

import numpy as np

from lipgen.rig.scene import Material, MeshItem, srgb_to_linear

__all__: list[str] = []


def _matrix(pose: np.ndarray):
    from mathutils import Matrix

    return Matrix([list(map(float, row)) for row in pose])


def _set_geometry(me, item: MeshItem) -> None:
    me.vertices.foreach_set("co", item.vertices.astype(np.float32).ravel())
    me.update()
    me.normals_split_custom_set_from_vertices(item.normals.astype(np.float32))


def _image(bpy, texture: np.ndarray):
    h, w, _ = texture.shape
    img = bpy.data.images.new(f"tex:{id(texture)}", w, h, alpha=False)
    rgba = np.concatenate([texture[::-1], np.full((h, w, 1), 255, np.uint8)], axis=2)
    img.colorspace_settings.name = "sRGB"
    img.pixels.foreach_set((rgba.astype(np.float32) / 255.0).ravel())
    img.update()  # not packed: packing a generated image would regenerate it blank
    return img


def _world_nodes(world, ambient: np.ndarray, background: np.ndarray) -> None:
    """The world: ``ambient`` radiance for every ray but camera rays, which see ``background``."""
    if world.node_tree is None:  # Blender < 5 (use_nodes is deprecated from 5.0)
        world.use_nodes = True
    nt = world.node_tree
    nt.nodes.clear()
    path = nt.nodes.new("ShaderNodeLightPath")
    amb, bg = nt.nodes.new("ShaderNodeBackground"), nt.nodes.new("ShaderNodeBackground")
    amb.inputs["Color"].default_value = (*map(float, ambient), 1.0)
    bg.inputs["Color"].default_value = (*map(float, background), 1.0)
    mix = nt.nodes.new("ShaderNodeMixShader")
    out = nt.nodes.new("ShaderNodeOutputWorld")
    nt.links.new(path.outputs["Is Camera Ray"], mix.inputs[0])
    nt.links.new(amb.outputs[0], mix.inputs[1])
    nt.links.new(bg.outputs[0], mix.inputs[2])
    nt.links.new(mix.outputs[0], out.inputs["Surface"])


def _principled(bpy, mat: Material, image, sss_radius):
    """A Principled BSDF material (dielectric, specular F0 0.04 as pyrender's), textured when
    ``image`` is given, with subsurface scattering of radius ``sss_radius`` (mm) when given;
    back faces are see-through unless the material is double-sided (pyrender culls them)."""
    m = bpy.data.materials.new(mat.name)
    if m.node_tree is None:
        m.use_nodes = True
    nt = m.node_tree
    nt.nodes.clear()
    bsdf = nt.nodes.new("ShaderNodeBsdfPrincipled")
    color = (*map(float, srgb_to_linear(mat.color)), 1.0)
    bsdf.inputs["Base Color"].default_value = color
    bsdf.inputs["Roughness"].default_value = float(mat.roughness)
    bsdf.inputs["Metallic"].default_value = 0.0
    bsdf.inputs["Alpha"].default_value = float(getattr(mat, "opacity", 1.0))  # faint ink (smudge halos)
    if image is not None:
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = image
        tex.interpolation = "Linear"
        uv = nt.nodes.new("ShaderNodeUVMap")
        uv.uv_map = "uv"
        mul = nt.nodes.new("ShaderNodeMix")
        mul.data_type, mul.blend_type = "RGBA", "MULTIPLY"
        # the Mix node has float, vector and colour sockets of the same names: take the colour ones
        a, b = (next(x for x in mul.inputs if x.identifier == f"{n}_Color") for n in "AB")
        result = next(x for x in mul.outputs if x.identifier == "Result_Color")
        mul.inputs["Factor"].default_value = 1.0
        nt.links.new(uv.outputs["UV"], tex.inputs["Vector"])
        nt.links.new(tex.outputs["Color"], a)
        b.default_value = color
        nt.links.new(result, bsdf.inputs["Base Color"])
    if sss_radius is not None:
        bsdf.subsurface_method = "BURLEY"  # diffusion on the surface: right for open shells
        bsdf.inputs["Subsurface Weight"].default_value = 1.0
        bsdf.inputs["Subsurface Radius"].default_value = tuple(map(float, sss_radius))
        bsdf.inputs["Subsurface Scale"].default_value = 1.0
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    if mat.double_sided:
        nt.links.new(bsdf.outputs[0], out.inputs["Surface"])
    else:
        geo = nt.nodes.new("ShaderNodeNewGeometry")
        clear = nt.nodes.new("ShaderNodeBsdfTransparent")
        mix = nt.nodes.new("ShaderNodeMixShader")
        nt.links.new(geo.outputs["Backfacing"], mix.inputs[0])
        nt.links.new(bsdf.outputs[0], mix.inputs[1])
        nt.links.new(clear.outputs[0], mix.inputs[2])
        nt.links.new(mix.outputs[0], out.inputs["Surface"])
    return m
