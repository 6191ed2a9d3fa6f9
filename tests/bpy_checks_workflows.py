"""More checks of the Blender add-on, run inside a Blender worker (see blender_session.py): the
artist's own mesh, undo of every operator, USD export, viseme scripts. Helpers: bpy_checks_addon."""

from __future__ import annotations

import bpy
import numpy as np
from bpy_checks_addon import _addon, _sheet, add_lips, call_error, evaluated, fitted_model, fresh, set_group

from lipgen import lip_mesh
from lipgen.fem import Physics
from lipgen.modes.model import ModeModel


# ---- the artist's own mesh ---------------------------------------------------------------------
def check_user_mesh() -> dict:
    fresh()
    obj = _sheet("MyLips", island=True)
    msgs = {}
    msgs["no_group"] = call_error(bpy.ops.object.lipgen_setup_mesh)
    V = np.array([v.co for v in obj.data.vertices])
    edge = np.flatnonzero(V[:, 1] < V[:, 1].min() + 1e-6)
    set_group(obj, "LipGen Anchors", edge)
    msgs["singular"] = call_error(bpy.ops.object.lipgen_setup_mesh)  # the island floats free
    assert not obj.lipgen.enabled
    msgs["broken"] = call_error(_setup_other, name="Sliver")
    obj = _sheet("MyLips2")
    V = np.array([v.co for v in obj.data.vertices])
    edge = np.flatnonzero(V[:, 1] < V[:, 1].min() + 1e-6)
    set_group(obj, "LipGen Anchors", edge)
    set_group(obj, "Inner", np.flatnonzero(V[:, 1] > V[:, 1].max() - 0.004))
    obj.lipgen.ridge_group = "Inner"
    assert bpy.ops.object.lipgen_setup_mesh() == {"FINISHED"}
    s = obj.lipgen
    assert s.enabled and abs(s.unit_mm - 1000.0) < 1e-9
    from blender_addon import bridge, lipobject

    spec = lipobject.physics_spec(obj)
    assert (spec.regions == 1).sum() > 0, "the ridge group made ridge faces"
    assert len(spec.faces) == 2 * len(obj.data.polygons), "quads become two triangles each"
    # A force on the artist's mesh matches the core on the same mesh (in mm).
    mesh = spec.mesh()
    phys = Physics(mesh, stiffness=dict(spec.stiffness), poisson=spec.poisson)
    top = np.flatnonzero(V[:, 1] > V[:, 1].max() - 1e-6)
    set_group(obj, "LipGen Force", top)
    assert bpy.ops.object.lipgen_apply_force(group="LipGen Force", units="FORCE", direction=(0, 0, 1),
                                             magnitude=0.2) == {"FINISHED"}
    F = np.zeros((mesh.n_nodes, 3))
    F[top] = [0.0, 0.0, 0.2]
    U = phys.displace(F)
    dev = float(np.abs((evaluated(obj) - bridge.rest_vertices(obj)) * 1000.0 - U).max())
    return {"messages": msgs, "force_max_dev_mm": dev, "peak_mm": float(np.abs(U).max())}


def _setup_other(name: str):
    obj = _sheet(name, sliver=True)
    V = np.array([v.co for v in obj.data.vertices])
    set_group(obj, "LipGen Anchors", np.flatnonzero(V[:, 1] < V[:, 1].min() + 1e-6))
    return bpy.ops.object.lipgen_setup_mesh()


# ---- undo -------------------------------------------------------------------------------------
def _state() -> dict:
    out = {}
    for ob in bpy.data.objects:
        keys = ob.data.shape_keys
        out[ob.name] = {
            "keys": None if keys is None else {kb.name: tuple(np.round(
                np.array([tuple(d.co) for d in kb.data]).ravel(), 6)) for kb in keys.key_blocks},
            "groups": sorted(g.name for g in ob.vertex_groups),
            "modes": [(m.name, round(m.value, 9)) for m in ob.lipgen.modes],
            "enabled": ob.lipgen.enabled,
            "n_vertices": len(ob.data.vertices),
            "force_group": ob.lipgen.force_group,
            "attrs": sorted(a.name for a in ob.data.attributes if not a.name.startswith(".")),
            "action": None if ob.animation_data is None or ob.animation_data.action is None
            else ob.animation_data.action.name,
        }
    return out


def _speech_wav(tmp: str) -> str | None:
    """A short spoken sentence (eSpeak NG) as a WAV, or None without pocketsphinx or espeak-ng."""
    import importlib.util

    from lipgen.speech import espeak
    from lipgen.speech.audio import write_wav

    if importlib.util.find_spec("pocketsphinx") is None or not espeak.available():
        return None
    audio, _ = espeak.synthesize("Two blue fish swam.")
    write_wav(f"{tmp}/fish.wav", audio)
    return f"{tmp}/fish.wav"


def check_undo(tmp: str) -> dict:
    fresh()
    fitted_model(f"{tmp}/model.npz")
    with open(f"{tmp}/curves.csv", "w") as fh:
        fh.write("frame,a,b\n1,0.5,0.1\n9,-0.5,0.2\n")
    undone = []

    def undoable(op, prepare=None, **kw):
        if prepare is not None:
            prepare()
        scene = bpy.context.scene
        scene.frame_set(scene.frame_current)  # sliders show their animated values, as after undo
        bpy.ops.ed.undo_push(message=f"before {op.idname()}")
        before = _state()
        assert op("EXEC_DEFAULT", True, **kw) == {"FINISHED"}, op
        after = _state()
        assert after != before, f"{op.idname()} changed nothing"
        bpy.ops.ed.undo()
        assert _state() == before, f"undo after {op.idname()} did not restore the scene"
        bpy.ops.ed.redo()
        assert _state() == after, f"redo after {op.idname()} did not restore its result"
        undone.append(op.idname_py())

    undoable(bpy.ops.object.lipgen_add_lips, resolution=0)
    obj = bpy.context.active_object
    name = obj.name
    undoable(bpy.ops.object.lipgen_load_modes, filepath=f"{tmp}/model.npz")
    undoable(bpy.ops.object.lipgen_clear_modes)
    undoable(bpy.ops.object.lipgen_build_modes, n_modes=3)
    undoable(bpy.ops.object.lipgen_key_modes)
    undoable(bpy.ops.object.lipgen_import_curves, filepath=f"{tmp}/curves.csv")
    undoable(bpy.ops.object.lipgen_train_modes, source="ANIMATION", n_modes=2)
    undoable(bpy.ops.object.lipgen_animate_visemes, script="AA:0.2 M:0.1")
    wav = _speech_wav(tmp)
    if wav is not None:  # needs pocketsphinx and espeak-ng (test_blender_speech.py says why not)
        undoable(bpy.ops.object.lipgen_animate_audio, filepath=wav, transcript="Two blue fish swam.")

    def select_markers():
        ob = bpy.data.objects[name]
        sel = np.zeros(len(ob.data.vertices), bool)
        sel[lip_mesh(0).markers[:3]] = True
        ob.data.vertices.foreach_set("select", sel)

    undoable(bpy.ops.object.lipgen_assign_group, prepare=select_markers, group="Pushed", role="force_group")
    undoable(bpy.ops.object.lipgen_apply_force, group="Pushed", magnitude=0.5)
    undoable(bpy.ops.object.lipgen_reach_start)

    def move_one():
        kb = bpy.data.objects[name].data.shape_keys.key_blocks["LipGen Reach"]
        kb.data[int(lip_mesh(0).markers[0])].co.y += 1.0

    undoable(bpy.ops.object.lipgen_reach_solve, prepare=move_one)

    def move_another():
        kb = bpy.data.objects[name].data.shape_keys.key_blocks["LipGen Reach"]
        kb.data[int(lip_mesh(0).markers[5])].co.x += 0.5

    undoable(bpy.ops.object.lipgen_reach_live, prepare=move_another)

    def cracked_sheet():
        from bpy_checks_hardening import _cracked_sheet

        bpy.context.view_layer.objects.active = _cracked_sheet("Cracked")[0]

    undoable(bpy.ops.object.lipgen_weld_cracks, prepare=cracked_sheet)

    def own_sheet():
        sheet = _sheet("Sheet")
        V = np.array([v.co for v in sheet.data.vertices])
        set_group(sheet, "LipGen Anchors", np.flatnonzero(V[:, 1] < V[:, 1].min() + 1e-6))

    undoable(bpy.ops.object.lipgen_setup_mesh, prepare=own_sheet)
    # Build Physics and Export USD change no Blender data (a status line, a file); undoing
    # right after them must leave the scene as it was.
    for op, kw in ((bpy.ops.object.lipgen_build_physics, {}),
                   (bpy.ops.object.lipgen_export_usd, {"filepath": f"{tmp}/undo.usda"})):
        bpy.ops.ed.undo_push(message=f"before {op.idname()}")
        before = _state()
        assert op("EXEC_DEFAULT", True, **kw) == {"FINISHED"}
        bpy.ops.ed.undo()
        assert _state() == before, op.idname()
        undone.append(op.idname_py())
    return {"undone": undone, "speech": wav is not None}


# ---- USD ----------------------------------------------------------------------------------------
def world_mm(obj) -> np.ndarray:
    """(n, 3) evaluated world positions in mm."""
    M = np.array(obj.matrix_world)
    co = evaluated(obj)
    return (co @ M[:3, :3].T + M[:3, 3]) * 1000.0


def check_usd_export(tmp: str) -> dict:
    """Export with lipgen.usd (the operator) and with Blender's own exporter; re-import the
    latter. Returns what the outer test validates with usd-core in a plain process."""
    fresh()
    model = fitted_model(f"{tmp}/model.npz")
    obj = add_lips(0)
    bpy.ops.object.lipgen_load_modes(filepath=f"{tmp}/model.npz")
    k = len(model.components_)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, 12
    rng = np.random.default_rng(5)
    keyed = np.array([1, 6, 12])
    sliders = rng.uniform(0.0, 1.0, (3, k))  # in [0, 1]: importers clamp to the default range
    coef = sliders * np.sqrt(model.explained_variance_)
    np.savez(f"{tmp}/curves.npz", coefficients=coef, frames=keyed)
    assert bpy.ops.object.lipgen_import_curves(filepath=f"{tmp}/curves.npz") == {"FINISHED"}
    frames = np.arange(1, 13)
    model_mm, world = [], []
    for f in frames:
        scene.frame_set(int(f))
        model_mm.append(evaluated(obj))  # mesh data of our lips is the model frame in mm
        world.append(world_mm(obj))
    scene.frame_set(1)
    assert bpy.ops.object.lipgen_export_usd(filepath=f"{tmp}/lipgen.usda", content="BOTH") == {"FINISHED"}
    assert bpy.ops.wm.usd_export(filepath=f"{tmp}/blender.usda", export_shapekeys=True,
                                 export_animation=True, selected_objects_only=False) == {"FINISHED"}
    keys_before = sorted(kb.name for kb in obj.data.shape_keys.key_blocks)
    # Re-import Blender's file into an empty scene: the shape keys and their animation return.
    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert bpy.ops.wm.usd_import(filepath=f"{tmp}/blender.usda") == {"FINISHED"}
    meshes = [o for o in bpy.data.objects if o.type == "MESH"]
    assert len(meshes) == 1
    back = meshes[0]
    keys_after = sorted(kb.name for kb in back.data.shape_keys.key_blocks)
    scene = bpy.context.scene
    reimported = []
    for f in frames:
        scene.frame_set(int(f))
        reimported.append(world_mm(back))
    np.savez(f"{tmp}/frames.npz", frames=frames, model_mm=np.array(model_mm),
             coef=np.array([[np.interp(f, keyed, coef[:, i]) for i in range(k)] for f in frames]))
    return {"keys_before": keys_before, "keys_after": keys_after,
            "reimport_max_dev_mm": float(np.abs(np.array(reimported) - np.array(world)).max()),
            "peak_mm": float(np.abs(np.array(model_mm) - lip_mesh(0).vertices).max())}


# ---- speech -------------------------------------------------------------------------------------
def check_visemes() -> dict:
    """Train modes on the performer's gestures, animate a viseme script; every frame equals the
    core's ModeModel.synthesize(project(performer's displacement))."""
    from lipgen.subject.activation import random_activations, viseme_activations
    from lipgen.subject.motion import default_subject

    fresh()
    obj = add_lips(0)
    assert bpy.ops.object.lipgen_train_modes(source="SPEECH", n_modes=8) == {"FINISHED"}
    script = "AA:0.3 EE:0.2 OO M:0.15 F REST:0.2"
    assert bpy.ops.object.lipgen_animate_visemes(script=script, start_frame=10) == {"FINISHED"}
    # The core, independently: the performer on lip_mesh(1), whose first 201 nodes are lip_mesh(0).
    lm = lip_mesh(0)
    subject = default_subject(0, 1)
    n = lm.n_nodes
    train = subject.displacements(random_activations(240, seed=0, fps=30.0))[:, :n]
    model = ModeModel(8).fit(train, mesh=lm)
    scene = bpy.context.scene
    fps = scene.render.fps / scene.render.fps_base
    U = subject.displacements(viseme_activations(script, fps=fps))[:, :n]
    devs, follow = [], []
    for i in range(0, len(U), 3):
        scene.frame_set(10 + i)
        want = model.synthesize(model.project(U[i]))
        devs.append(float(np.abs(evaluated(obj) - lm.vertices - want).max()))
        follow.append(float(np.abs(want - U[i]).max()))
    refused = ""
    sheet = _sheet("NotLips")
    V = np.array([v.co for v in sheet.data.vertices])
    set_group(sheet, "LipGen Anchors", np.flatnonzero(V[:, 1] < V[:, 1].min() + 1e-6))
    bpy.ops.object.lipgen_setup_mesh()
    bpy.ops.object.lipgen_build_modes(n_modes=2)
    refused = call_error(bpy.ops.object.lipgen_animate_visemes, script="AA")
    return {"max_dev_mm": max(devs), "frames": len(U), "peak_mm": float(np.abs(U).max()),
            "modes_follow_performer_mm": max(follow), "refusal": refused}


# ---- files --------------------------------------------------------------------------------------
def check_save_reload(tmp: str) -> dict:
    """Everything LipGen keeps lives in the .blend (sliders, drivers, groups, settings); the
    physics is rebuilt on first use after opening the file."""
    from blender_addon import bridge
    from lipgen.blender import clear_physics_cache
    from lipgen.blender.physics_cache import cached_count

    fresh()
    obj = add_lips(0)
    model = fitted_model(f"{tmp}/model.npz")
    bpy.ops.object.lipgen_load_modes(filepath=f"{tmp}/model.npz")
    lm = lip_mesh(0)
    set_group(obj, "LipGen Force", lm.markers[:2])
    obj.lipgen.modes[1].value = 0.8
    path = f"{tmp}/lips.blend"
    assert bpy.ops.wm.save_as_mainfile(filepath=path) == {"FINISHED"}
    bpy.ops.wm.read_factory_settings(use_empty=True)
    clear_physics_cache()
    assert bpy.ops.wm.open_mainfile(filepath=path) == {"FINISHED"}
    obj = bpy.data.objects["LipGen Lips"]
    bpy.context.view_layer.objects.active = obj
    coef = np.zeros(len(model.components_))
    coef[1] = 0.8 * obj.lipgen.modes[1].scale
    dev_modes = float(np.abs(evaluated(obj) - lm.vertices - model.synthesize(coef)).max())
    obj.lipgen.modes[1].value = 0.0  # the driver still follows the slider
    dev_zero = float(np.abs(evaluated(obj) - lm.vertices - model.synthesize(np.zeros_like(coef))).max())
    assert cached_count() == 0
    assert bpy.ops.object.lipgen_apply_force(group="LipGen Force", units="FORCE", direction=(0, -1, 0),
                                             magnitude=1.0) == {"FINISHED"}
    assert cached_count() == 1
    F = np.zeros((lm.n_nodes, 3))
    F[lm.markers[:2]] = [0.0, 0.0, 1.0]
    kb = obj.data.shape_keys.key_blocks["LipGen Force"]
    dev_force = float(np.abs(bridge.shape_key_co(kb) - lm.vertices - Physics(lm).displace(F)).max())
    return {"modes_max_dev_mm": dev_modes, "zero_max_dev_mm": dev_zero, "force_max_dev_mm": dev_force}


# ---- panels -------------------------------------------------------------------------------------
class _Layout:
    """Stands in for bpy.types.UILayout (which only Blender's UI can make): records every call
    and checks that each property and operator a panel names exists."""

    def __init__(self, log):
        self.log = log

    def _sub(self, *a, **kw):
        return _Layout(self.log)

    row = column = box = split = _sub

    def label(self, **kw):
        self.log.append(("label", kw.get("text", "")))

    def prop(self, data, name, **kw):
        assert name in data.bl_rna.properties, f"{type(data).__name__} has no property {name!r}"
        self.log.append(("prop", name))

    def prop_search(self, data, name, search_data, search_name, **kw):
        assert name in data.bl_rna.properties and search_name in search_data.bl_rna.properties
        self.log.append(("prop_search", name))

    def operator(self, idname, **kw):
        mod, name = idname.split(".")
        assert hasattr(getattr(bpy.ops, mod), name), f"no operator {idname}"
        self.log.append(("operator", idname))

        class _Props:
            pass

        return _Props()


def check_panels_draw() -> dict:
    fresh()
    addon = _addon()
    panels = [c for c in addon.classes if issubclass(c, bpy.types.Panel)]
    drawn = {}

    def draw_all():
        for cls in panels:
            if hasattr(cls, "poll") and not cls.poll(bpy.context):
                continue
            log = []
            cls.draw(type("P", (), {"layout": _Layout(log)})(), bpy.context)
            drawn.setdefault(cls.__name__, set()).update(name for kind, name in log if kind != "label")

    draw_all()  # nothing selected
    obj = add_lips(0)
    draw_all()
    bpy.ops.object.lipgen_build_modes(n_modes=2)
    obj.lipgen.force_preview = True
    draw_all()
    return {k: sorted(v) for k, v in drawn.items()}


# ---- training from a dataset --------------------------------------------------------------------
def check_train_from_dataset(folder: str) -> dict:
    """Modes trained on a lipgen dataset's true vertices (its finer subject mesh, nested) equal
    the core's ModeModel fitted on the same frames' first nodes."""
    from lipgen.dataset.layout import Dataset

    fresh()
    obj = add_lips(0)
    assert bpy.ops.object.lipgen_train_modes(source="DATASET", filepath=folder, n_modes=4) == {"FINISHED"}
    lm = lip_mesh(0)
    ds = Dataset(folder)
    n = lm.n_nodes
    U = np.array([f.truth["vertices"][:n] - ds.mesh.vertices[:n] for f in ds])
    model = ModeModel(4).fit(U, mesh=lm)
    coef = model.project(U[len(U) // 2])
    for i, item in enumerate(obj.lipgen.modes):
        item.value = coef[i] / item.scale
    dev = float(np.abs(evaluated(obj) - lm.vertices - model.synthesize(coef)).max())
    sheet = _sheet("NotLips")
    V = np.array([v.co for v in sheet.data.vertices])
    set_group(sheet, "LipGen Anchors", np.flatnonzero(V[:, 1] < V[:, 1].min() + 1e-6))
    bpy.ops.object.lipgen_setup_mesh()
    refused = call_error(bpy.ops.object.lipgen_train_modes, source="DATASET", filepath=folder)
    return {"max_dev_mm": dev, "frames": len(U), "peak_mm": float(np.abs(U).max()), "refusal": refused}
