"""Stage authoring for :mod:`lipgen.usd`: the prims of each encoding, written with ``pxr``.

Everything here takes a plan of plain numpy arrays (:class:`Plan`) and an open stage; the
public checks, file handling and the choice of what to write live in :mod:`lipgen.usd`.
Time samples are set at the Sdf level (one call per frame inside a change block), which is
what keeps 10,000 frames well under a second.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Plan", "author_stage", "ENCODING_SET", "BLEND_SHAPES", "BAKED_POINTS"]

ENCODING_SET = "encoding"
"""Name of the variant set that holds both encodings when both are written."""
BLEND_SHAPES, BAKED_POINTS = "blendShapes", "bakedPoints"


@dataclass(frozen=True)
class Plan:
    """What to write, as arrays (mm, model frame).

    Attributes
    ----------
    root, mesh_name, markers_name : str
        Prim names (valid identifiers).
    faces : (m, 3) int
    regions : list of (name, (j,) int face indices)
        Non-empty regions, a partition of the faces.
    times : (F,) float
        Time codes of the frames (empty for a still stage).
    rest : (n, 3) float32 or None
        Rest points of the blend-shape encoding (mesh vertices + model mean).
    shape_names : list of str
        One token per blend shape, in weight order.
    offsets : (s, n, 3) float32
        Blend-shape offsets.
    shape_weights : (F, s) float32
        Blend-shape weights per frame.
    skel_extent : (2, 3) float32 or None
        Conservative bound over every frame of the blend-shape encoding.
    baked : (F, n, 3) float32 or None
        Baked points per frame.
    marker_nodes : (q,) int
    marker_names : tuple of str
    attrs : dict
        Extra ``lipgen:*`` attributes on the mesh (name -> float64 array).
    """

    root: str
    mesh_name: str
    markers_name: str
    faces: np.ndarray
    regions: list
    times: np.ndarray
    rest: np.ndarray | None
    shape_names: list
    offsets: np.ndarray
    shape_weights: np.ndarray
    skel_extent: np.ndarray | None
    baked: np.ndarray | None
    marker_nodes: np.ndarray
    marker_names: tuple
    attrs: dict


def float_extent(points: np.ndarray, pad: float = 0.0) -> np.ndarray:
    """(2, 3) float32 box that contains ``points (..., 3)``, widened by ``pad`` and rounded outward."""
    flat = np.asarray(points, np.float64).reshape(-1, 3)
    lo, hi = flat.min(axis=0) - pad, flat.max(axis=0) + pad
    lo32 = lo.astype(np.float32)
    hi32 = hi.astype(np.float32)
    lo32 = np.where(lo32 > lo, np.nextafter(lo32, np.float32(-np.inf)), lo32)
    hi32 = np.where(hi32 < hi, np.nextafter(hi32, np.float32(np.inf)), hi32)
    return np.stack([lo32, hi32])


def _vec3f(a):
    from pxr import Vt

    return Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(a, dtype=np.float32))


def _set_samples(stage, attr, times: np.ndarray, values, convert) -> None:
    """Time samples on ``attr`` in the current edit target, one Sdf call per frame."""
    from pxr import Sdf

    layer = stage.GetEditTarget().GetLayer()
    spec_path = stage.GetEditTarget().MapToSpecPath(attr.GetPath())
    with Sdf.ChangeBlock():
        for t, v in zip(times, values, strict=True):
            layer.SetTimeSample(spec_path, float(t), convert(v))


def _author_topology(stage, plan: Plan, mesh_path):
    from pxr import UsdGeom, Vt

    mesh = UsdGeom.Mesh.Define(stage, mesh_path)
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(plan.faces), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(plan.faces.astype(np.int32).ravel()))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    mesh.CreateDoubleSidedAttr(True)  # an open surface: both sides are seen
    for name, idx in plan.regions:
        UsdGeom.Subset.CreateGeomSubset(mesh, name, UsdGeom.Tokens.face,
                                        Vt.IntArray.FromNumpy(idx.astype(np.int32)), "region",
                                        UsdGeom.Tokens.partition)
    for key, value in plan.attrs.items():
        from pxr import Sdf

        attr = mesh.GetPrim().CreateAttribute(f"lipgen:{key}", Sdf.ValueTypeNames.DoubleArray,
                                              custom=True)
        attr.Set(Vt.DoubleArray.FromNumpy(np.asarray(value, np.float64).ravel()))
    return mesh


def _author_markers_base(stage, plan: Plan, path):
    from pxr import Sdf, UsdGeom, Vt

    pts = UsdGeom.Points.Define(stage, path)
    pts.CreateWidthsAttr(Vt.FloatArray([1.0]))
    pts.SetWidthsInterpolation(UsdGeom.Tokens.constant)
    names = pts.GetPrim().CreateAttribute("lipgen:markerNames", Sdf.ValueTypeNames.StringArray, custom=True)
    names.Set(Vt.StringArray(list(plan.marker_names)))
    nodes = pts.GetPrim().CreateAttribute("lipgen:markerNodes", Sdf.ValueTypeNames.IntArray, custom=True)
    nodes.Set(Vt.IntArray.FromNumpy(plan.marker_nodes.astype(np.int32)))
    return pts


def _bind_blend_shapes(stage, prim, skel_path, names, offsets) -> None:
    """SkelBindingAPI on ``prim``: the skeleton, one rigid joint influence, and a BlendShape child
    per name with its offsets."""
    from pxr import Gf, UsdSkel, Vt

    binding = UsdSkel.BindingAPI.Apply(prim)
    binding.CreateSkeletonRel().SetTargets([skel_path])
    # Every point rigidly on the one dummy joint, whose transforms are all identity: skinning
    # leaves the points as the blend shapes made them, in every consumer.
    binding.CreateJointIndicesPrimvar(True, 1).Set(Vt.IntArray([0]))
    binding.CreateJointWeightsPrimvar(True, 1).Set(Vt.FloatArray([1.0]))
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))
    binding.CreateBlendShapesAttr(Vt.TokenArray(list(names)))
    targets = []
    for name, off in zip(names, offsets, strict=True):
        shape = UsdSkel.BlendShape.Define(stage, prim.GetPath().AppendChild(name))
        shape.CreateOffsetsAttr(_vec3f(off))
        targets.append(shape.GetPath())
    binding.CreateBlendShapeTargetsRel().SetTargets(targets)


def _author_blend_shapes(stage, plan: Plan, root_path, mesh_path, markers_path) -> None:
    from pxr import Gf, UsdGeom, UsdSkel, Vt

    skel = UsdSkel.Skeleton.Define(stage, root_path.AppendChild("Skel"))
    skel.CreateJointsAttr(Vt.TokenArray(["root"]))
    skel.CreateBindTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(1.0)]))
    skel.CreateRestTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(1.0)]))
    anim = UsdSkel.Animation.Define(stage, skel.GetPath().AppendChild("Anim"))
    anim.CreateJointsAttr(Vt.TokenArray(["root"]))
    anim.CreateTranslationsAttr(Vt.Vec3fArray([Gf.Vec3f(0.0)]))
    anim.CreateRotationsAttr(Vt.QuatfArray([Gf.Quatf(1.0)]))
    anim.CreateScalesAttr(Vt.Vec3hArray([Gf.Vec3h(1.0)]))
    anim.CreateBlendShapesAttr(Vt.TokenArray(plan.shape_names))
    weights = anim.CreateBlendShapeWeightsAttr()
    weights.Set(Vt.FloatArray(len(plan.shape_names)))  # all zero: the rest shape (mesh + mean)
    if len(plan.times):
        _set_samples(stage, weights, plan.times, plan.shape_weights, Vt.FloatArray.FromNumpy)
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])

    mesh = UsdGeom.Mesh.Get(stage, mesh_path)
    mesh.CreatePointsAttr(_vec3f(plan.rest))
    mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(float_extent(plan.rest)))
    _bind_blend_shapes(stage, mesh.GetPrim(), skel.GetPath(), plan.shape_names, plan.offsets)
    if markers_path is not None:
        pts = UsdGeom.Points.Get(stage, markers_path)
        rest = plan.rest[plan.marker_nodes]
        pts.CreatePointsAttr(_vec3f(rest))
        pts.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(float_extent(rest, pad=0.5)))  # widths 1 mm
        _bind_blend_shapes(stage, pts.GetPrim(), skel.GetPath(), plan.shape_names,
                           plan.offsets[:, plan.marker_nodes])
    root = UsdGeom.Boundable(stage.GetPrimAtPath(root_path))
    root.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(plan.skel_extent))


def _set_points(stage, prim, times, frames, boxes) -> None:
    """``points`` and ``extent`` of a PointBased prim: one sample a frame, or plain values for a
    still prim (no times)."""
    points_attr, extent_attr = prim.CreatePointsAttr(), prim.CreateExtentAttr()
    if len(times):
        _set_samples(stage, points_attr, times, frames, _vec3f)
        _set_samples(stage, extent_attr, times, boxes, _vec3f)
    else:
        points_attr.Set(_vec3f(frames[0]))
        extent_attr.Set(_vec3f(boxes[0]))


def _author_baked(stage, plan: Plan, root_path, mesh_path, markers_path) -> None:
    from pxr import UsdGeom, Vt

    mesh = UsdGeom.Mesh.Get(stage, mesh_path)
    frames = plan.baked
    boxes = np.stack([frames.min(axis=1), frames.max(axis=1)], axis=1)  # float32 min/max: exact
    _set_points(stage, mesh, plan.times, frames, boxes)
    if markers_path is not None:
        mk = frames[:, plan.marker_nodes]
        half_width = np.float32(0.5)  # the markers' widths are 1 mm
        mk_boxes = np.stack([mk.min(axis=1) - half_width, mk.max(axis=1) + half_width], axis=1)
        _set_points(stage, UsdGeom.Points.Get(stage, markers_path), plan.times, mk, mk_boxes)
    root = stage.GetPrimAtPath(root_path)
    if root.IsA(UsdGeom.Boundable):
        UsdGeom.Boundable(root).CreateExtentAttr(Vt.Vec3fArray.FromNumpy(float_extent(frames)))


def author_stage(stage, plan: Plan, default_encoding: str = BLEND_SHAPES) -> None:
    """Write ``plan`` into the empty ``stage``: the root prim, the mesh, and one or both encodings.

    With both encodings the root holds a variant set ``encoding`` with variants
    ``blendShapes`` and ``bakedPoints``; the topology, regions and markers are authored once,
    outside the variants, and each variant adds only its own opinions.
    """
    from pxr import Kind, Sdf, Usd, UsdGeom, UsdSkel

    has_skel, has_baked = plan.rest is not None, plan.baked is not None
    root_path = Sdf.Path.absoluteRootPath.AppendChild(plan.root)
    root = (UsdSkel.Root if has_skel else UsdGeom.Xform).Define(stage, root_path).GetPrim()
    Usd.ModelAPI(root).SetKind(Kind.Tokens.component)
    stage.SetDefaultPrim(root)
    mesh_path = root_path.AppendChild(plan.mesh_name)
    markers_path = root_path.AppendChild(plan.markers_name) if len(plan.marker_nodes) else None
    _author_topology(stage, plan, mesh_path)
    if markers_path is not None:
        _author_markers_base(stage, plan, markers_path)
    if has_skel and has_baked:
        vset = root.GetVariantSets().AddVariantSet(ENCODING_SET)
        for name, writer in ((BLEND_SHAPES, _author_blend_shapes), (BAKED_POINTS, _author_baked)):
            vset.AddVariant(name)
            vset.SetVariantSelection(name)
            with vset.GetVariantEditContext():
                writer(stage, plan, root_path, mesh_path, markers_path)
        vset.SetVariantSelection(default_encoding)
    elif has_skel:
        _author_blend_shapes(stage, plan, root_path, mesh_path, markers_path)
    elif has_baked:
        _author_baked(stage, plan, root_path, mesh_path, markers_path)
    else:
        raise ValueError("nothing to write: the plan has neither blend shapes nor baked points")
