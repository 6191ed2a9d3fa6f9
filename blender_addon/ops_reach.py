"""Reach goals (thesis eq 4.3, App. A): move a few vertices, the physics moves the rest.

The artist drags vertices of a shape key ("LipGen Reach"). Every vertex that moved since the
last solve becomes a goal, and so stay the goals of earlier solves (vertex group "LipGen
Goals"); the minimum-norm force that puts the goals exactly where they are moves every other
vertex with least strain. *Solve Reach* does it once. *Live Reach* does it while the artist
drags, in Edit Mode, from a window timer (a modal operator, not a handler).
"""

from __future__ import annotations

import bmesh
import bpy
import numpy as np
from bpy.props import BoolProperty, FloatProperty, StringProperty

from lipgen.blender import moved_nodes, reach_goals

from . import bridge, lipobject
from .lipobject import REACH_KEY, UserError
from .ops_common import USER_ERRORS, LipgenOperator, lipgen_object

GOALS_GROUP = "LipGen Goals"
SOLVED_ATTR = "lipgen_reach_solved"
"""Point attribute: the reach key as last solved, to tell newly moved vertices from followers."""


class ReachSession:
    """The goals, the last solved shape and the physics of one object's reach key.

    Built in Object Mode (it reads the goals group, the solved attribute and the physics).
    """

    def __init__(self, obj, threshold: float = 1e-3) -> None:
        self.unit = obj.lipgen.unit_mm
        self.rest = bridge.rest_vertices(obj)
        spec = lipobject.physics_spec(obj)
        self.physics = lipobject.physics_for_object(obj, spec)
        self.anchors = spec.anchors
        solved = bridge.point_vectors(obj.data, SOLVED_ATTR)
        self.last = self.rest.copy() if solved is None else solved
        self.goals: set[int] = set()
        if obj.vertex_groups.get(GOALS_GROUP) is not None:
            self.goals.update(bridge.vertex_group_nodes(obj, GOALS_GROUP).tolist())
        self.threshold = float(threshold)

    def moved(self, target: np.ndarray) -> np.ndarray:
        return moved_nodes(self.last * self.unit, target * self.unit, self.threshold)

    def solve(self, target: np.ndarray, extra_goals=()):
        """Goals := moved vertices + earlier goals + ``extra_goals``; returns (goals, U mm, shape)."""
        self.goals.update(self.moved(target).tolist())
        self.goals.update(int(i) for i in extra_goals)
        u = self.unit
        rg = reach_goals(self.rest * u, target * u, sorted(self.goals), self.anchors)
        U, _ = self.physics.reach(rg.dofs, rg.values)
        new = self.rest + np.asarray(U) / u
        self.last = new
        self.goals = set(rg.nodes.tolist())
        return rg, np.asarray(U), new

    def store(self, obj) -> None:
        """Keep the goals (vertex group) and the solved shape (attribute) on the object."""
        bridge.set_point_vectors(obj.data, SOLVED_ATTR, self.last)
        bridge.set_vertex_group(obj, GOALS_GROUP, sorted(self.goals))


def live_step(session: ReachSession, obj) -> int:
    """One Live Reach update in Edit Mode: if goals moved, move every other vertex.

    Returns the number of vertices that moved since the last update (0: nothing to do).
    Goal vertices are not written, so a running grab keeps full control of them.
    """
    bm = bmesh.from_edit_mesh(obj.data)
    co = bridge.edit_vertices(bm)
    n_moved = len(session.moved(co))
    if n_moved == 0:
        return 0
    rg, _U, new = session.solve(co)
    followers = np.setdiff1d(np.arange(len(co)), rg.nodes)
    bridge.set_edit_vertices(bm, new, followers)
    bmesh.update_edit_mesh(obj.data, loop_triangles=False, destructive=False)
    return n_moved


def _reach_key(obj, name: str, create: bool):
    keys = obj.data.shape_keys
    kb = None if keys is None else keys.key_blocks.get(name)
    if kb is None and create:
        kb = bridge.ensure_shape_key(obj, name, bridge.rest_vertices(obj), (-10.0, 10.0))
        kb.value = 1.0
    if kb is None:
        raise UserError(f"no shape key {name!r}: press New Reach Shape, move a few vertices of "
                        "it in Edit Mode, then Solve Reach")
    obj.active_shape_key_index = list(obj.data.shape_keys.key_blocks).index(kb)
    return kb


class OBJECT_OT_lipgen_reach_start(LipgenOperator, bpy.types.Operator):
    """Start a reach edit: a fresh shape key to drag a few vertices on; Solve Reach moves the rest"""

    bl_idname = "object.lipgen_reach_start"
    bl_label = "New Reach Shape"

    name: StringProperty(name="Shape key", default=REACH_KEY)
    edit: BoolProperty(name="Enter Edit Mode", default=False, options={"SKIP_SAVE"})

    def invoke(self, context, event):
        self.edit = True
        return self.execute(context)

    def run(self, context):
        obj = lipgen_object(context)
        rest = bridge.rest_vertices(obj)
        kb = bridge.ensure_shape_key(obj, self.name, rest, (-10.0, 10.0))
        kb.value = 1.0
        bridge.remove_driver(kb)
        if obj.vertex_groups.get(GOALS_GROUP) is not None:
            obj.vertex_groups.remove(obj.vertex_groups[GOALS_GROUP])
        bridge.set_point_vectors(obj.data, SOLVED_ATTR, None)
        _reach_key(obj, self.name, create=False)
        obj.data.update()
        if self.edit:
            bpy.ops.object.mode_set(mode="EDIT")


class OBJECT_OT_lipgen_reach_solve(LipgenOperator, bpy.types.Operator):
    """Solve the reach shape: moved vertices stay, the physics moves the rest with least strain (eq 4.3)"""

    bl_idname = "object.lipgen_reach_solve"
    bl_label = "Solve Reach"

    name: StringProperty(name="Shape key", default=REACH_KEY)
    threshold: FloatProperty(name="Moved by more than (mm)", default=1e-3, min=0.0, precision=4,
                             description="A vertex counts as moved (a goal) beyond this distance")
    hold_selected: BoolProperty(name="Hold selected", default=False,
                                description="Selected vertices that did not move stay in place")

    def run(self, context):
        solve_once(self, lipgen_object(context), self.name, self.threshold, self.hold_selected)


def solve_once(op, obj, name: str, threshold: float, hold_selected: bool = False) -> None:
    """Solve the reach key once (Object Mode) and report what happened through ``op``."""
    kb = _reach_key(obj, name, create=False)
    session = ReachSession(obj, threshold)
    extra = bridge.selected_vertices(obj.data) if hold_selected else ()
    rg, U, new = session.solve(bridge.shape_key_co(kb), extra)
    bridge.set_shape_key_co(kb, new)
    session.store(obj)
    obj.data.update()
    obj.update_tag()
    msg = f"{len(rg.nodes)} goal vertices, peak displacement {np.linalg.norm(U, axis=1).max():.3g} mm"
    if len(rg.skipped_anchors):
        op.report({"WARNING"}, msg + f"; {len(rg.skipped_anchors)} anchored vertices cannot move "
                  "and were ignored")
    else:
        op.report({"INFO"}, msg)


class OBJECT_OT_lipgen_reach_live(LipgenOperator, bpy.types.Operator):
    """Drag vertices in Edit Mode and the lips follow as you go (Esc, Enter or Tab stops)"""

    bl_idname = "object.lipgen_reach_live"
    bl_label = "Live Reach"

    name: StringProperty(name="Shape key", default=REACH_KEY)
    threshold: FloatProperty(name="Moved by more than (mm)", default=1e-3, min=0.0, precision=4)
    interval: FloatProperty(name="Update every (s)", default=0.05, min=0.01, max=1.0)

    def run(self, context):
        # Without a window to drag in (scripts, background): one solve of the reach key.
        solve_once(self, lipgen_object(context), self.name, self.threshold)

    def invoke(self, context, event):
        try:
            obj = lipgen_object(context)
            _reach_key(obj, self.name, create=True)
            self._session = ReachSession(obj, self.threshold)
        except USER_ERRORS as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        bpy.ops.object.mode_set(mode="EDIT")
        wm = context.window_manager
        self._timer = wm.event_timer_add(self.interval, window=context.window)
        wm.modal_handler_add(self)
        self.report({"INFO"}, "Live Reach: drag vertices (G); Esc, Enter or Tab to stop")
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        obj = context.active_object
        if (obj is None or obj.mode != "EDIT" or event.type == "ESC"
                or (event.type in ("RET", "NUMPAD_ENTER") and event.value == "PRESS")):
            return self._finish(context, obj)
        if event.type == "TIMER":
            try:
                live_step(self._session, obj)
            except USER_ERRORS as exc:
                self.report({"ERROR"}, str(exc))
                return self._finish(context, obj)
        return {"PASS_THROUGH"}

    def _finish(self, context, obj):
        context.window_manager.event_timer_remove(self._timer)
        if obj is not None and obj.type == "MESH":
            if obj.mode == "EDIT":
                bpy.ops.object.mode_set(mode="OBJECT")
            self._session.store(obj)
            obj.data.update()
        return {"FINISHED"}


classes = (OBJECT_OT_lipgen_reach_start, OBJECT_OT_lipgen_reach_solve, OBJECT_OT_lipgen_reach_live)
