"""Checks of the add-on's physics tools (forces, live preview, reach, live reach), run inside a
Blender worker (see blender_session.py). Helpers: bpy_checks_addon."""

from __future__ import annotations

import bpy
import numpy as np
from bpy_checks_addon import add_lips, evaluated, fresh, set_group

from lipgen import lip_mesh
from lipgen.fem import Physics


# ---- forces and reach -------------------------------------------------------------------------
def check_force(resolution: int = 0) -> dict:
    fresh()
    obj = add_lips(resolution)
    lm = lip_mesh(resolution)
    phys = Physics(lm)
    nodes = lm.markers[[0, 2, 5]]
    set_group(obj, "LipGen Force", nodes)
    out = {}
    # One world direction: world -Y is the model's +z (out of the face).
    force = bpy.ops.object.lipgen_apply_force
    assert force(group="LipGen Force", units="FORCE", direction=(0, -1, 0), magnitude=0.7,
                 name="push") == {"FINISHED"}
    F = np.zeros((lm.n_nodes, 3))
    F[nodes] = [0.0, 0.0, 0.7]
    out["direction_max_dev_mm"] = float(np.abs(evaluated(obj) - lm.vertices - phys.displace(F)).max())
    out["peak_mm"] = float(np.abs(phys.displace(F)).max())
    obj.data.shape_keys.key_blocks["push"].value = 0.0
    # Along the normals.
    assert force(group="LipGen Force", units="FORCE", use_normal=True, magnitude=-0.4,
                 name="pull") == {"FINISHED"}
    F = np.zeros((lm.n_nodes, 3))
    F[nodes] = -0.4 * lm.vertex_normals()[nodes]
    out["normal_max_dev_mm"] = float(np.abs(evaluated(obj) - lm.vertices - phys.displace(F)).max())
    obj.data.shape_keys.key_blocks["pull"].value = 0.0
    # Keyframed: 0 -> 1 -> 0 around frame 10.
    bpy.context.scene.frame_set(10)
    assert force(group="LipGen Force", units="FORCE", direction=(1, 0, 0), magnitude=1.0,
                 result="KEYFRAME", ramp=4, name="key") == {"FINISHED"}
    F = np.zeros((lm.n_nodes, 3))
    F[nodes] = [1.0, 0.0, 0.0]
    U = phys.displace(F)
    worst = 0.0
    for frame, w in ((6, 0.0), (8, 0.5), (10, 1.0), (14, 0.0)):
        bpy.context.scene.frame_set(frame)
        worst = max(worst, float(np.abs(evaluated(obj) - lm.vertices - w * U).max()))
    out["keyframed_max_dev_mm"] = worst
    # Live preview: the settings' update callbacks write the preview key.
    bpy.context.scene.frame_set(1)
    s = obj.lipgen
    s.force_group = "LipGen Force"
    s.force_use_normal = False
    s.force_direction = (0.0, 0.0, 1.0)  # world +Z = model +y
    s.force_units = "FORCE"
    s.force_magnitude = 0.25
    s.force_preview = True
    assert "LipGen Preview" in obj.data.shape_keys.key_blocks, s.force_status
    s.force_magnitude = 0.5
    F = np.zeros((lm.n_nodes, 3))
    F[nodes] = [0.0, 0.5, 0.0]
    out["preview_max_dev_mm"] = float(np.abs(evaluated(obj) - lm.vertices - phys.displace(F)).max())
    # Magnitude as a peak displacement: the same force, scaled so the largest motion is 1.5 mm.
    s.force_units = "PEAK"
    s.force_magnitude = -1.5
    F = np.zeros((lm.n_nodes, 3))
    F[nodes] = [0.0, 1.0, 0.0]
    U = phys.displace(F)
    U *= -1.5 / np.linalg.norm(U, axis=1).max()
    got = evaluated(obj) - lm.vertices
    out["peak_preview_max_dev_mm"] = float(np.abs(got - U).max())
    out["peak_preview_mm"] = float(np.linalg.norm(got, axis=1).max())
    s.force_preview = False
    assert "LipGen Preview" not in obj.data.shape_keys.key_blocks
    return out


def check_reach() -> dict:
    fresh()
    obj = add_lips(0)
    lm = lip_mesh(0)
    phys = Physics(lm)
    assert bpy.ops.object.lipgen_reach_start() == {"FINISHED"}
    kb = obj.data.shape_keys.key_blocks["LipGen Reach"]
    goals = {int(lm.markers[1]): (0.0, 1.5, 0.5), int(lm.markers[9]): (0.0, -1.0, 0.0)}
    for node, d in goals.items():
        kb.data[node].co = tuple(np.array(lm.vertices[node]) + d)
    assert bpy.ops.object.lipgen_reach_solve() == {"FINISHED"}
    nodes = np.array(sorted(goals))
    from lipgen.fem import dofs

    U, _ = phys.reach(dofs(nodes), np.array([goals[n] for n in nodes]).ravel())
    first = float(np.abs(evaluated(obj) - lm.vertices - U).max())
    # A second drag: the first goals stay goals, the followers are not frozen.
    node3 = int(lm.markers[4])
    kb.data[node3].co = tuple(np.array(kb.data[node3].co) + (0.3, 0.0, 0.0))
    target3 = np.array(kb.data[node3].co) - lm.vertices[node3]
    assert bpy.ops.object.lipgen_reach_solve() == {"FINISHED"}
    goals[node3] = tuple(target3)
    nodes = np.array(sorted(goals))
    U2, _ = phys.reach(dofs(nodes), np.array([goals[n] for n in nodes]).ravel())
    second = float(np.abs(evaluated(obj) - lm.vertices - U2).max())
    return {"first_max_dev_mm": first, "second_max_dev_mm": second,
            "peak_mm": float(np.abs(U2).max())}


def check_live_reach() -> dict:
    """Live Reach's update step in Edit Mode (what its timer runs): the dragged vertices stay,
    the others follow, equal to the core's reach; the goals are kept when it stops."""
    import bmesh

    from blender_addon import bridge
    from blender_addon.ops_reach import GOALS_GROUP, ReachSession, live_step
    from lipgen.fem import dofs

    fresh()
    obj = add_lips(0)
    lm = lip_mesh(0)
    phys = Physics(lm)
    assert bpy.ops.object.lipgen_reach_start() == {"FINISHED"}
    session = ReachSession(obj)
    bpy.ops.object.mode_set(mode="EDIT")
    devs = []
    goals = {}
    for node, d in ((int(lm.markers[3]), (0.0, 2.0, 0.0)), (int(lm.markers[11]), (0.5, 0.0, 1.0))):
        bm = bmesh.from_edit_mesh(obj.data)
        bm.verts.ensure_lookup_table()
        bm.verts[node].co = tuple(lm.vertices[node] + d)  # the artist drags one vertex
        goals[node] = d
        assert live_step(session, obj) == 1
        assert live_step(session, obj) == 0  # nothing moved since: no work
        nodes = np.array(sorted(goals))
        U, _ = phys.reach(dofs(nodes), np.array([goals[n] for n in nodes]).ravel())
        got = bridge.edit_vertices(bmesh.from_edit_mesh(obj.data))
        devs.append(float(np.abs(got - lm.vertices - U).max()))
    bpy.ops.object.mode_set(mode="OBJECT")
    session.store(obj)
    kb = obj.data.shape_keys.key_blocks["LipGen Reach"]
    key_dev = float(np.abs(bridge.shape_key_co(kb) - lm.vertices - U).max())
    assert sorted(bridge.vertex_group_nodes(obj, GOALS_GROUP).tolist()) == sorted(goals)
    # From a script the operator solves once (no window to drag in).
    assert bpy.ops.object.lipgen_reach_live() == {"FINISHED"}
    return {"step_max_dev_mm": max(devs), "key_max_dev_mm": key_dev}
