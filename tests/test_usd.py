"""USD export, checked by USD's own evaluation (UsdSkel), its validators, and Blender.

Precision. USD stores points, blend-shape offsets and weights as float32 and evaluates blend
shapes in float32, so the deformed points cannot equal the float64 ``ModeModel.synthesize``
to 1e-6 mm in absolute terms once coordinates pass 16 mm (one float32 step there is 1.9e-6).
The tests hold every point to the first-order float32 bound of the sum USD evaluates,
``(s + 4) * u * (|rest| + sum_i |w_i| |offset_i|)`` with ``u = 2**-24`` and ``s`` shapes, and
the relative error (to the largest coordinate) to below 1e-6.
"""

import numpy as np
import pytest

pytest.importorskip("pxr")

from usd_common import expected_points  # noqa: E402

from lipgen import TopologyMismatchError
from lipgen.mesh.lipmesh import LipMesh  # noqa: E402
from lipgen.modes.model import ModeModel  # noqa: E402
from lipgen.usd import export as usd  # noqa: E402

pytestmark = pytest.mark.usd
U32 = 2.0**-24


def _float32_bound(mesh, model, weights, shapes):
    """Per-point bound of the float32 evaluation error of rest + sum w_i offset_i."""
    std = np.sqrt(model.explained_variance_)
    offs = np.abs(model.components_ * std[:, None]).reshape(len(std), -1, 3)
    rest = np.abs(mesh.vertices + model.mean_.reshape(-1, 3))
    mag = rest + np.einsum("fk,knc->fnc", np.abs(weights / std), offs)
    return (shapes + 4) * U32 * mag


@pytest.mark.parametrize("ext,weight_range", [(".usda", "signed"), (".usdc", "signed"),
                                              (".usdz", "signed"), (".usdc", "unit")])
def test_usdskel_points_equal_synthesize(tmp_path, usd_mesh, usd_fitted, ext, weight_range):
    model, weights = usd_fitted
    path = usd.export_usd(tmp_path / f"lips{ext}", usd_mesh, model, weights, fps=24,
                          weight_range=weight_range)
    anim = usd.read_animation(path)
    want = expected_points(usd_mesh, model, weights)
    assert anim.skinned and anim.points.shape == want.shape
    assert np.array_equal(anim.times, np.arange(len(weights)))
    err = np.abs(anim.points - want)
    shapes = 10 if weight_range == "signed" else 20
    assert np.all(err <= _float32_bound(usd_mesh, model, weights, shapes)), err.max()
    assert err.max() / np.abs(want).max() < 1e-6
    # The markers are bound to the same skeleton and follow the lips exactly as well.
    marks = usd.read_animation(path, prim="/Lips/markers")
    assert np.abs(marks.points - want[:, usd_mesh.markers]).max() <= err.max() + 1e-12


def test_blend_shape_query_agrees_with_baked_skinning(tmp_path, usd_mesh, usd_fitted):
    """A second UsdSkel route (BlendShapeQuery, no skinning) gives the same points."""
    from pxr import Usd, UsdSkel, Vt

    model, weights = usd_fitted
    path = usd.export_usd(tmp_path / "lips.usdc", usd_mesh, model, weights)
    stage = Usd.Stage.Open(str(path))
    binding = UsdSkel.BindingAPI(stage.GetPrimAtPath(f"/Lips/{usd_mesh.name}"))
    query = UsdSkel.BlendShapeQuery(binding)
    anim = UsdSkel.Animation(stage.GetPrimAtPath("/Lips/Skel/Anim"))
    assert list(anim.GetBlendShapesAttr().Get()) == [f"mode{i:02d}" for i in range(10)]
    indices, offsets = query.ComputeBlendShapePointIndices(), query.ComputeSubShapePointOffsets()
    rest = binding.GetPrim().GetAttribute("points").Get()
    baked = usd.read_animation(path).points
    for f in range(len(weights)):
        w = anim.GetBlendShapeWeightsAttr().Get(f)
        sub_w, bs_idx, sub_idx = query.ComputeSubShapeWeights(w)
        pts = Vt.Vec3fArray(rest)
        assert query.ComputeDeformedPoints(sub_w, bs_idx, sub_idx, indices, offsets, pts)
        assert np.array_equal(np.asarray(pts, np.float64), baked[f])
    # Scale: offsets are the components times each mode's standard deviation, kept on the mesh,
    # so the coefficients come back as weight * scale.
    std = np.sqrt(model.explained_variance_)
    scale = np.asarray(binding.GetPrim().GetAttribute("lipgen:modeScale").Get())
    assert np.allclose(scale, std)
    coef = np.stack([np.asarray(anim.GetBlendShapeWeightsAttr().Get(f)) for f in range(len(weights))]) * scale
    assert np.allclose(coef, weights, rtol=1e-6, atol=1e-6 * np.abs(weights).max())
    got = np.stack([np.asarray(o, np.float64).ravel() for o in offsets if len(o)])  # drop null shapes
    assert np.allclose(got, model.components_ * std[:, None], atol=4 * U32 * np.abs(got).max())


def test_baked_points_extents_and_stage_metadata(tmp_path, usd_mesh, usd_fitted):
    from pxr import Usd, UsdGeom

    model, weights = usd_fitted
    points = expected_points(usd_mesh, model, weights) + 0.3  # any animation, not only the model's
    path = usd.export_usd(tmp_path / "both.usda", usd_mesh, model, weights, points, fps=25, start=1)
    anim = usd.read_animation(path)  # the default variant: blend shapes
    assert anim.skinned and np.array_equal(anim.times, np.arange(1, 25))
    stage = Usd.Stage.Open(str(path))
    assert UsdGeom.GetStageUpAxis(stage) == "Y" and UsdGeom.GetStageMetersPerUnit(stage) == 0.001
    assert stage.GetTimeCodesPerSecond() == 25 and stage.GetFramesPerSecond() == 25
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (1, 24)
    root = stage.GetDefaultPrim()
    assert root.GetPath() == "/Lips" and root.GetTypeName() == "SkelRoot"
    vset = root.GetVariantSets().GetVariantSet("encoding")
    assert vset.GetVariantNames() == ["bakedPoints", "blendShapes"]
    assert vset.GetVariantSelection() == "blendShapes"
    meshp = UsdGeom.Mesh(stage.GetPrimAtPath(f"/Lips/{usd_mesh.name}"))
    assert meshp.GetSubdivisionSchemeAttr().Get() == "none"
    subsets = UsdGeom.Subset.GetGeomSubsets(meshp, "face", "region")
    assert sorted(s.GetPrim().GetName() for s in subsets) == sorted(usd_mesh.region_names)
    assert UsdGeom.Subset.ValidateFamily(meshp, "face", "region")[0]
    assert sorted(np.concatenate([np.asarray(s.GetIndicesAttr().Get()) for s in subsets])) == list(
        range(usd_mesh.n_faces))
    # The SkelRoot's extent contains every frame of the UsdSkel evaluation.
    box = np.asarray(UsdGeom.Boundable(root).GetExtentAttr().Get(), np.float64)
    assert np.all(anim.points >= box[0]) and np.all(anim.points <= box[1])
    # Switch to the baked variant: exactly the float32 points, each sample's extent holds them.
    vset.SetVariantSelection("bakedPoints")
    stage.GetRootLayer().Export(str(tmp_path / "baked.usda"))
    baked = usd.read_animation(tmp_path / "baked.usda")
    assert not baked.skinned
    assert np.array_equal(baked.points, points.astype(np.float32).astype(np.float64))
    ext = meshp.GetExtentAttr()
    assert ext.GetTimeSamples() == list(range(1, 25))
    for f, t in enumerate(ext.GetTimeSamples()):
        lo, hi = np.asarray(ext.Get(t), np.float64)
        assert np.all(baked.points[f] >= lo) and np.all(baked.points[f] <= hi)
    marks = usd.read_animation(tmp_path / "baked.usda", prim="/Lips/markers")
    assert np.array_equal(marks.points, baked.points[:, usd_mesh.markers])


@pytest.mark.parametrize("kind", ["modes", "baked", "both", "still"])
def test_validators_report_no_errors(tmp_path, usd_mesh, usd_fitted, kind):
    model, weights = usd_fitted
    points = expected_points(usd_mesh, model, weights)
    args = {"modes": (model, weights, None), "baked": (None, None, points),
            "both": (model, weights, points), "still": (model, None, None)}[kind]
    for ext in (".usda", ".usd", ".usdz"):
        path = usd.export_usd(tmp_path / f"{kind}{ext}", usd_mesh, *args)
        issues = usd.validate(path)
        assert not [str(i) for i in issues if i.is_error]


def test_validate_checks_every_variant(tmp_path, usd_mesh, usd_fitted):
    """A fault planted only in the variant that is not selected is still found."""
    from pxr import Usd, UsdGeom

    model, weights = usd_fitted
    points = expected_points(usd_mesh, model, weights)
    path = usd.export_usd(tmp_path / "both.usda", usd_mesh, model, weights, points)
    stage = Usd.Stage.Open(str(path))
    vset = stage.GetDefaultPrim().GetVariantSets().GetVariantSet("encoding")
    vset.SetVariantSelection("bakedPoints")
    with vset.GetVariantEditContext():
        stage.DefinePrim("/Lips/junk")  # typeless, so not imageable
        UsdGeom.Subset.Define(stage, "/Lips/junk/subset")
    vset.SetVariantSelection("blendShapes")
    stage.Save()
    found = [(i.variant, i.name) for i in usd.validate(path) if i.is_error]
    assert found and all(v == "encoding=bakedPoints" for v, _ in found), found
    assert not [i for i in usd.validate(path, all_variants=False) if i.is_error]


def test_validate_finds_real_problems(tmp_path):
    """The validators run: a stage without upAxis, metersPerUnit or defaultPrim is reported."""
    from pxr import Usd, UsdGeom

    p = tmp_path / "bare.usda"
    stage = Usd.Stage.CreateNew(str(p))
    UsdGeom.Mesh.Define(stage, "/m")
    stage.Save()
    names = {i.name for i in usd.validate(p) if i.is_error}
    assert {"MissingDefaultPrim", "MissingUpAxisMetadata", "MissingMetersPerUnitMetadata"} <= names


def test_read_animation_other_files_with_joints_units_and_transforms(tmp_path):
    """A file not made by lipgen: z-up, centimetres, a transformed SkelRoot, a blend shape plus a
    joint that translates; the expected points are computed by hand."""
    from pxr import Gf, Usd, UsdGeom, UsdSkel, Vt

    p = tmp_path / "other.usda"
    st = Usd.Stage.CreateNew(str(p))
    UsdGeom.SetStageUpAxis(st, "Z")
    UsdGeom.SetStageMetersPerUnit(st, 0.01)
    root = UsdSkel.Root.Define(st, "/R")
    UsdGeom.Xformable(root).AddTranslateOp().Set(Gf.Vec3d(1, 2, 3))
    skel = UsdSkel.Skeleton.Define(st, "/R/S")
    skel.CreateJointsAttr(["j"])
    skel.CreateBindTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(1)]))
    skel.CreateRestTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(1)]))
    anim = UsdSkel.Animation.Define(st, "/R/S/A")
    anim.CreateJointsAttr(["j"])
    anim.CreateBlendShapesAttr(["b"])
    anim.CreateRotationsAttr(Vt.QuatfArray([Gf.Quatf(1)]))
    anim.CreateScalesAttr(Vt.Vec3hArray([Gf.Vec3h(1)]))
    for t in range(3):
        anim.CreateTranslationsAttr().Set(Vt.Vec3fArray([Gf.Vec3f(0, 0, t)]), t)
        anim.CreateBlendShapeWeightsAttr().Set(Vt.FloatArray([0.5 * t]), t)
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    m = UsdGeom.Mesh.Define(st, "/R/M")
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    m.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(V))
    m.CreateFaceVertexCountsAttr([3])
    m.CreateFaceVertexIndicesAttr([0, 1, 2])
    b = UsdSkel.BindingAPI.Apply(m.GetPrim())
    b.CreateSkeletonRel().SetTargets([skel.GetPath()])
    b.CreateJointIndicesPrimvar(True, 1).Set([0])
    b.CreateJointWeightsPrimvar(True, 1).Set([1.0])
    b.CreateBlendShapesAttr(["b"])
    shape = UsdSkel.BlendShape.Define(st, "/R/M/b")
    shape.CreateOffsetsAttr(Vt.Vec3fArray([Gf.Vec3f(2, 0, 0)] * 3))
    b.CreateBlendShapeTargetsRel().SetTargets([shape.GetPath()])
    st.SetDefaultPrim(root.GetPrim())
    st.Save()
    anim_out = usd.read_animation(p)
    t = np.arange(3.0)
    want = (V[None] + np.array([1.0, 0, 0]) * t[:, None, None] + np.array([0, 0, 1.0]) * t[:, None, None]
            + np.array([1.0, 2, 3])) * 10.0  # blend shape, joint, root transform, cm -> mm
    assert anim_out.skinned and anim_out.up_axis == "Z"
    assert np.allclose(anim_out.points, want, atol=1e-5)


def test_writes_are_atomic(tmp_path, usd_mesh, usd_fitted, monkeypatch):
    model, weights = usd_fitted
    for ext in (".usda", ".usdz"):
        dest = tmp_path / f"keep{ext}"
        dest.write_bytes(b"previous file")

        def broken(layer, tmp, ext, stem):
            tmp.write_bytes(b"#usda 1.0\n(half a file")
            raise OSError("disk full (simulated)")

        monkeypatch.setattr(usd, "_write_layer", broken)
        with pytest.raises(OSError, match="simulated"):
            usd.export_usd(dest, usd_mesh, model, weights)
        monkeypatch.undo()
        assert dest.read_bytes() == b"previous file"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.usda", "keep.usdz"]
    usd.export_usd(tmp_path / "keep.usda", usd_mesh, model, weights)  # a later write replaces it whole
    assert usd.read_animation(tmp_path / "keep.usda").points.shape == (len(weights), usd_mesh.n_nodes, 3)


def test_bad_inputs_are_named_and_write_nothing(tmp_path, usd_mesh, usd_fitted):
    model, weights = usd_fitted
    cases = [
        (dict(path=tmp_path / "x.obj"), ValueError, r"unknown extension '\.obj'.*\.usda"),
        (dict(weights=weights[:, :7]), ValueError, r"shape \(F, 10\).*10 modes.*\(24, 7\)"),
        (dict(weights=np.where(np.arange(10) == 3, np.nan, weights)), ValueError,
         r"weights has 24 non-finite.*index \(0, 3\)"),
        (dict(weights=weights[0]), ValueError, r"shape \(F, 10\).*\(10,\)"),
        (dict(points=np.zeros((24, 5, 3))), ValueError, r"points must have shape"),
        (dict(points=np.zeros((3, usd_mesh.n_nodes, 3))), ValueError, "24 frames but points has 3"),
        (dict(model=None), ValueError, "weights were given without a model"),
        (dict(fps=0), ValueError, "fps must be a positive"),
        (dict(weight_range="clamped"), ValueError, "weight_range must be"),
    ]
    for override, exc, pattern in cases:
        kw = dict(path=tmp_path / "out.usda", mesh=usd_mesh, model=model, weights=weights)
        kw.update(override)
        with pytest.raises(exc, match=pattern):
            usd.export_usd(**kw)
    other = ModeModel(3).fit(np.random.default_rng(0).normal(size=(8, 10, 3)))
    small = LipMesh(np.eye(3) * 10, [[0, 1, 2]])
    with pytest.raises(TopologyMismatchError):
        usd.export_usd(tmp_path / "out.usda", small, other)
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(FileNotFoundError):
        usd.read_animation(tmp_path / "missing.usda")


def _blender(tmp_path, usd_path, widen=False):
    """What Blender (pip bpy, in the shared Blender session's process: it bundles its own USD)
    makes of a file."""
    import importlib.util
    from pathlib import Path

    if importlib.util.find_spec("bpy") is None:  # finds without importing it here
        pytest.skip("the pip bpy module is not installed")
    from blender_session import shared_session

    out = tmp_path / (Path(usd_path).stem + ".npz")
    try:
        shared_session().run("blender_usd_probe:main", str(usd_path), str(out), widen)
    except SystemExit as e:  # the probe's own refusals (no mesh, a failed import)
        pytest.fail(f"Blender could not import {usd_path}: {e}")
    return dict(np.load(out))


@pytest.mark.blender
def test_blender_imports_shape_keys_with_animation(tmp_path, usd_mesh, usd_fitted):
    """Blender imports the blend shapes as shape keys with their weight curves; its evaluated
    vertices (depsgraph, object space) match synthesize within the float32 bound of its own
    shape-key sum (twice the USD bound: Blender first stores basis + offset as each key)."""
    model, weights = usd_fitted
    want = expected_points(usd_mesh, model, weights)
    for weight_range, widen in (("unit", False), ("signed", True)):
        path = usd.export_usd(tmp_path / f"lips_{weight_range}.usdc", usd_mesh, model, weights, fps=24,
                              weight_range=weight_range)
        got = _blender(tmp_path, path, widen=widen)
        shapes = 10 if weight_range == "signed" else 20
        names = [f"mode{i:02d}" for i in range(10)] if shapes == 10 else [
            f"mode{i:02d}_{s}" for i in range(10) for s in ("pos", "neg")]
        assert list(got["key_names"]) == ["Basis", *names]
        assert np.array_equal(got["frames"], np.arange(len(weights)))
        err = np.abs(got["coords"] - want)
        assert np.all(err <= 2 * _float32_bound(usd_mesh, model, weights, shapes)), err.max()
        # Units and axes go to the object transform: mm -> m and y-up -> Blender's z-up.
        R = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]) * 0.001
        assert np.allclose(got["world"][:3, :3], R)


@pytest.mark.blender
def test_blender_imports_baked_points(tmp_path, usd_mesh, usd_fitted):
    model, weights = usd_fitted
    points = expected_points(usd_mesh, model, weights) - 0.2
    path = usd.export_usd(tmp_path / "baked.usda", usd_mesh, points=points, fps=24)
    got = _blender(tmp_path, path)
    assert np.array_equal(got["coords"], points.astype(np.float32))
