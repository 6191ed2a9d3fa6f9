"""Checks of the Blender add-on, run inside a Blender worker process (see blender_session.py).

Every check starts from an empty factory scene, drives the add-on only through ``bpy.ops``,
reads the result back from the depsgraph (the evaluated mesh, as Blender would render it) and
compares it with the core (``lipgen.fem.Physics``, ``lipgen.modes.ModeModel``) computed here
independently of the add-on's code. Checks return the measured deviations.
"""

from __future__ import annotations

import math

import bpy
import numpy as np

from lipgen import lip_mesh
from lipgen.fem import Physics
from lipgen.modes.model import ModeModel

ADDON = "blender_addon"


# ---- set-up ---------------------------------------------------------------------------------
def _addon():
    import importlib

    return importlib.import_module(ADDON)


def fresh() -> None:
    """An empty scene with the add-on registered and the undo system initialised."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if not hasattr(bpy.types, "OBJECT_OT_lipgen_add_lips"):
        _addon().register()
    bpy.ops.ed.undo_push(message="start")


def evaluated(obj) -> np.ndarray:
    """Object-space vertex positions from the depsgraph (float64 copy of Blender's float32)."""
    dg = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(dg)
    me = ev.to_mesh()
    co = np.empty(3 * len(me.vertices), np.float32)
    me.vertices.foreach_get("co", co)
    ev.to_mesh_clear()
    return co.reshape(-1, 3).astype(np.float64)


def add_lips(resolution: int = 0):
    assert bpy.ops.object.lipgen_add_lips(resolution=resolution) == {"FINISHED"}
    return bpy.context.active_object


def training_frames(mesh, physics, n_frames: int, seed: int, peak_mm: float = 15.0) -> np.ndarray:
    """Displacements from random forces on random markers (the core's own physics), scaled so
    the largest vertex motion over all frames is ``peak_mm`` (the physics is linear)."""
    rng = np.random.default_rng(seed)
    F = np.zeros((n_frames, mesh.n_nodes, 3))
    for f in range(n_frames):
        nodes = rng.choice(mesh.markers, size=4, replace=False)
        F[f, nodes] = rng.normal(0.0, 1.0, (4, 3))
    U = physics.displace(F)
    return U * (peak_mm / np.linalg.norm(U, axis=2).max())


def fitted_model(path: str, resolution: int = 0, n_modes: int = 6, seed: int = 0) -> ModeModel:
    lm = lip_mesh(resolution)
    model = ModeModel(n_modes=n_modes).fit(training_frames(lm, Physics(lm), 40, seed), mesh=lm)
    model.save(path)
    return model


def set_group(obj, name: str, nodes) -> None:
    vg = obj.vertex_groups.get(name) or obj.vertex_groups.new(name=name)
    vg.remove(range(len(obj.data.vertices)))
    vg.add([int(i) for i in nodes], 1.0, "REPLACE")


def call_error(op, **kw) -> str:
    """Run an operator that must refuse; return its error report."""
    try:
        op(**kw)
    except RuntimeError as exc:
        return str(exc)
    raise AssertionError(f"{op} did not refuse")


# ---- registration -----------------------------------------------------------------------------
def check_register_twice() -> dict:
    addon = _addon()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if hasattr(bpy.types, "OBJECT_OT_lipgen_add_lips"):
        addon.unregister()
    for _ in range(2):
        addon.register()
        assert hasattr(bpy.types.Object, "lipgen")
        assert all(cls.is_registered for cls in addon.classes)
        ops = sorted(n for n in dir(bpy.ops.object) if n.startswith("lipgen_"))
        addon.unregister()
        assert not hasattr(bpy.types.Object, "lipgen")
        assert not any(cls.is_registered for cls in addon.classes)
    addon.register()
    for cls in addon.classes:
        if issubclass(cls, bpy.types.Operator):
            assert cls.bl_idname.startswith("object.lipgen_"), cls.bl_idname
            assert cls.__name__ == "OBJECT_OT_" + cls.bl_idname.split(".")[1]
            assert {"REGISTER", "UNDO"} <= set(cls.bl_options), cls.__name__
        if issubclass(cls, bpy.types.Panel):
            assert cls.bl_category == "LipGen"
    return {"operators": ops}


# ---- our lips ---------------------------------------------------------------------------------
def check_add_lips(resolution: int) -> dict:
    fresh()
    obj = add_lips(resolution)
    lm = lip_mesh(resolution)
    from blender_addon import bridge, lipobject

    V = bridge.mesh_vertices(obj.data)
    assert V.shape == lm.vertices.shape
    tris, poly = bridge.mesh_triangles(obj.data)
    assert np.array_equal(tris, lm.faces), "Blender's triangles must be lipgen's faces, in order"
    assert lipobject.topology_id(obj) == lm.topology_id == obj.lipgen.topology_id
    assert np.array_equal(lipobject.regions_per_triangle(obj, poly), lm.regions)
    groups = {g.name: bridge.vertex_group_nodes(obj, g.name) for g in obj.vertex_groups}
    assert np.array_equal(groups["LipGen Anchors"], np.sort(lm.anchors))
    assert np.array_equal(groups["LipGen Markers"], np.sort(lm.markers))
    for region in ("ridge", "strip", "skin"):
        assert np.array_equal(groups[f"LipGen {region.capitalize()}"], lm.region_nodes(region))
    # Upright at real size: the model's +y (up) is world +Z, its +z (out of the face) world -Y.
    M = np.array(obj.matrix_world)
    assert np.allclose(M[:3, :3] @ [0, 1, 0], [0, 0, 0.001], atol=1e-9)
    assert np.allclose(M[:3, :3] @ [0, 0, 1], [0, -0.001, 0], atol=1e-9)
    spec_mesh = lipobject.physics_spec(obj).mesh()
    return {"n_vertices": len(V), "max_vertex_error_mm": float(np.abs(V - lm.vertices).max()),
            "anchors": int(len(spec_mesh.anchors))}


# ---- modes ------------------------------------------------------------------------------------
def check_model_sliders(tmp: str) -> dict:
    """Loaded model: sliders through SUM drivers reproduce ModeModel.synthesize."""
    fresh()
    model = fitted_model(f"{tmp}/model.npz")
    obj = add_lips(0)
    assert bpy.ops.object.lipgen_load_modes(filepath=f"{tmp}/model.npz") == {"FINISHED"}
    s = obj.lipgen
    k = len(model.components_)
    assert len(s.modes) == k
    rest = lip_mesh(0).vertices
    for i, item in enumerate(s.modes):  # every mode key is driven by one SUM driver of its slider
        path = obj.data.shape_keys.key_blocks[f"LipGen {item.name}"].path_from_id("value")
        fc = obj.data.shape_keys.animation_data.drivers.find(path)
        assert fc.driver.type == "SUM" and len(fc.driver.variables) == 1
        var = fc.driver.variables[0]
        assert var.type == "SINGLE_PROP" and var.targets[0].id == obj
        assert var.targets[0].data_path == f"lipgen.modes[{i}].value"
    rng = np.random.default_rng(1)
    sd = np.sqrt(model.explained_variance_)
    out = {}
    single = np.zeros(k)
    single[0] = 1.5 * sd[0]
    for label, coef in (("single", single), ("typical", rng.normal(0, 1.0, k) * sd),
                        ("extreme", 3.0 * sd * np.sign(rng.normal(size=k)))):
        for i, item in enumerate(s.modes):
            item.value = coef[i] / item.scale
        got = evaluated(obj)
        want = rest + model.synthesize(coef)
        dev = np.abs(got - want)
        bound = float32_bound(obj, [1.0] + [m.value for m in s.modes],
                              ["LipGen Mean"] + [f"LipGen {m.name}" for m in s.modes])
        assert (dev <= bound).all(), f"{label}: deviation beyond the float32 bound"
        out[f"{label}_max_dev_mm"] = float(dev.max())
        out[f"{label}_bound_mm"] = float(bound.max())
        out[f"{label}_peak_mm"] = float(np.abs(want - rest).max())
    return out


def float32_bound(obj, weights, key_names) -> np.ndarray:
    """(n, 3) first-order bound on the rounding of Blender's float32 shape-key blend.

    Blender evaluates ``acc = basis; acc += w_i * (key_i - basis)`` in float32 from float32 keys.
    Each stored value, subtraction, product and sum adds at most u = 2^-24 of its magnitude.
    """
    u = 2.0**-24
    kb = obj.data.shape_keys.key_blocks
    from blender_addon import bridge

    b = np.abs(bridge.shape_key_co(obj.data.shape_keys.reference_key))
    total = b.copy()
    acc = b.copy()
    for w, name in zip(weights, key_names, strict=True):
        k = bridge.shape_key_co(kb[name])
        d = np.abs(k - bridge.shape_key_co(obj.data.shape_keys.reference_key))
        acc = acc + abs(w) * d
        total += abs(w) * (np.abs(k) + b + 2 * d) + acc
    return u * total


def check_keyframed_sliders(tmp: str) -> dict:
    """Coefficient curves (CSV) become keyframes; frames give synthesize() of the curve."""
    fresh()
    model = fitted_model(f"{tmp}/model.npz")
    obj = add_lips(0)
    bpy.ops.object.lipgen_load_modes(filepath=f"{tmp}/model.npz")
    k = len(model.components_)
    rng = np.random.default_rng(2)
    keyed_frames = np.array([1, 5, 9, 17])
    coef = rng.normal(0, 1, (len(keyed_frames), k)) * np.sqrt(model.explained_variance_)
    with open(f"{tmp}/curves.csv", "w") as fh:
        fh.write("frame," + ",".join(f"mode{i}" for i in range(k)) + "\n")
        for f, row in zip(keyed_frames, coef, strict=True):
            fh.write(f"{f}," + ",".join(repr(float(c)) for c in row) + "\n")
    assert bpy.ops.object.lipgen_import_curves(filepath=f"{tmp}/curves.csv") == {"FINISHED"}
    rest = lip_mesh(0).vertices
    scene = bpy.context.scene
    devs, bounds, peaks = [], [], []

    def compare(want_coef):
        got = evaluated(obj)
        want = rest + model.synthesize(want_coef)
        dev = np.abs(got - want)
        sliders = [m.value for m in obj.lipgen.modes]
        bound = float32_bound(obj, [1.0] + sliders, ["LipGen Mean"] + [f"LipGen {m.name}" for m in
                                                                        obj.lipgen.modes])
        # Keyframe values are float32 too: two stored keys and the interpolation, 3u each.
        offsets = [np.abs(evaluated_key(obj, f"LipGen {m.name}")) for m in obj.lipgen.modes]
        bound += 3 * 2.0**-24 * sum(abs(sv) * off for sv, off in zip(sliders, offsets, strict=True))
        assert (dev <= bound).all(), f"frame {scene.frame_current}: beyond the float32 bound"
        devs.append(float(dev.max()))
        bounds.append(float(bound.max()))
        peaks.append(float(np.abs(want - rest).max()))

    for frame in (1, 3, 5, 9, 13, 17):
        scene.frame_set(frame)
        compare(np.array([np.interp(frame, keyed_frames, coef[:, i]) for i in range(k)]))
    # An npz with times in seconds at the scene's fps lands on the same frames.
    fps = scene.render.fps / scene.render.fps_base
    np.savez(f"{tmp}/curves.npz", coefficients=-coef, times=(keyed_frames - 1) / fps)
    assert bpy.ops.object.lipgen_import_curves(filepath=f"{tmp}/curves.npz", start_frame=1) == {"FINISHED"}
    scene.frame_set(9)
    compare(-coef[2])
    return {"max_dev_mm": max(devs), "max_bound_mm": max(bounds), "max_peak_mm": max(peaks),
            "per_frame_dev_mm": devs, "per_frame_peak_mm": peaks}


def evaluated_key(obj, name: str) -> np.ndarray:
    """(n, 3) offset of shape key ``name`` from the Basis, as stored (float32)."""
    from blender_addon import bridge

    kb = obj.data.shape_keys.key_blocks
    return bridge.shape_key_co(kb[name]) - bridge.shape_key_co(obj.data.shape_keys.reference_key)


def check_topology_refusal(tmp: str) -> dict:
    fresh()
    fitted_model(f"{tmp}/model_r1.npz", resolution=1)
    obj = add_lips(0)
    msg_count = call_error(bpy.ops.object.lipgen_load_modes, filepath=f"{tmp}/model_r1.npz")
    assert "750" in msg_count and "201" in msg_count, msg_count
    # Same node count, different faces: a model fitted on a mesh whose faces are rewired.
    lm = lip_mesh(0)
    faces = lm.faces.copy()
    faces[[0, 1]] = faces[[1, 0]]
    from lipgen.mesh.lipmesh import LipMesh

    other = LipMesh(lm.vertices, faces, lm.regions[[1, 0, *range(2, lm.n_faces)]], lm.anchors, name="rewired")
    ModeModel(3).fit(training_frames(lm, Physics(lm), 10, 3), mesh=other).save(f"{tmp}/model_other.npz")
    msg_faces = call_error(bpy.ops.object.lipgen_load_modes, filepath=f"{tmp}/model_other.npz")
    assert "topology" in msg_faces, msg_faces
    assert len(obj.lipgen.modes) == 0 and obj.data.shape_keys.key_blocks.keys() == ["Basis"]
    return {"node_count_message": msg_count, "faces_message": msg_faces}


def check_physics_modes() -> dict:
    """Modes built in place are the softest eigenvectors of the grounded stiffness."""
    fresh()
    obj = add_lips(0)
    assert bpy.ops.object.lipgen_build_modes(n_modes=5) == {"FINISHED"}
    lm = lip_mesh(0)
    phys = Physics(lm)
    free = phys.free_dofs
    Kff = phys.K[free][:, free].toarray()
    lam, vec = np.linalg.eigh(Kff)
    s = obj.lipgen
    rest = lm.vertices.astype(np.float32).astype(np.float64)  # as Blender stores it
    worst_vec, worst_eval = 0.0, 0.0
    for i, item in enumerate(s.modes):
        for j, other in enumerate(s.modes):
            other.value = 1.0 if i == j else 0.0
        u = ((evaluated(obj) - rest) / item.scale).reshape(-1)
        assert np.abs(u[phys.anchored_dofs]).max() == 0.0
        v = vec[:, i]
        worst_vec = max(worst_vec, float(1.0 - abs(u[free] @ v) / np.linalg.norm(u[free])))
        rayleigh = (u[free] @ Kff @ u[free]) / (u[free] @ u[free])
        worst_eval = max(worst_eval, float(abs(rayleigh - lam[i]) / lam[i]))
    return {"max_1_minus_cos": worst_vec, "max_rel_eigenvalue_err": worst_eval,
            "eigenvalues": lam[:5].tolist()}


def check_train_from_shape_keys() -> dict:
    fresh()
    obj = add_lips(0)
    lm = lip_mesh(0)
    U = training_frames(lm, Physics(lm), 8, 4)
    for f, u in enumerate(U):
        kb = obj.shape_key_add(name=f"pose{f}", from_mix=False)
        kb.data.foreach_set("co", (lm.vertices + u).astype(np.float32).ravel())
        kb.value = 0.0
    assert bpy.ops.object.lipgen_train_modes(source="SHAPE_KEYS", n_modes=4) == {"FINISHED"}
    # What the core makes of the same shapes, as Blender stores them (float32).
    from blender_addon import bridge

    basis = bridge.shape_key_co(obj.data.shape_keys.reference_key)
    stored = np.array([bridge.shape_key_co(obj.data.shape_keys.key_blocks[f"pose{f}"]) - basis
                       for f in range(len(U))])
    model = ModeModel(4).fit(stored, mesh=lm)
    coef = model.project(stored[3])
    for i, item in enumerate(obj.lipgen.modes):
        item.value = coef[i] / item.scale
    got = evaluated(obj)
    return {"max_dev_mm": float(np.abs(got - lm.vertices - model.synthesize(coef)).max()),
            "reconstruct_pose_mm": float(np.abs(got - lm.vertices - stored[3]).max())}


# ---- the artist's own mesh --------------------------------------------------------------------
def _sheet(name: str, nx: int = 12, ny: int = 8, island: bool = False, sliver: bool = False):
    """A curved sheet of quads in metres (as artists model), with no LipGen set-up.

    ``island`` adds a loose triangle no anchor can hold; ``sliver`` a zero-area triangle.
    """
    x, y = np.meshgrid(np.linspace(-0.02, 0.02, nx), np.linspace(-0.01, 0.01, ny))
    V = np.column_stack([x.ravel(), y.ravel(), 0.01 * np.cos(x.ravel() / 0.04 * math.pi)])
    idx = np.arange(nx * ny).reshape(ny, nx)
    faces = [(int(idx[j, i]), int(idx[j, i + 1]), int(idx[j + 1, i + 1]), int(idx[j + 1, i]))
             for j in range(ny - 1) for i in range(nx - 1)]
    verts = V.tolist()
    if island:
        base = len(verts)
        verts += [[0.05, 0.0, 0.0], [0.06, 0.0, 0.0], [0.05, 0.01, 0.0]]
        faces.append((base, base + 1, base + 2))
    if sliver:
        a, b = int(idx[0, 0]), int(idx[0, 1])
        verts.append(list((V[a] + V[b]) / 2))
        faces.append((a, b, len(verts) - 1))
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    obj = bpy.data.objects.new(name, me)
    bpy.context.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    return obj
