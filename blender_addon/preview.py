"""The live force preview: a shape key rewritten whenever a force setting changes.

Property update callbacks (not handlers) call :func:`update`. The expensive parts (reading the
vertex groups, the factorised physics, the unit responses of the selection) are kept per object
in a *session*; dragging the magnitude or turning the direction only forms a weighted sum of the
stored responses and writes one shape key. A session is thrown away when the mesh's rest shape,
topology or physics settings change (checked cheaply on every update), and when the preview is
switched on, the vertex group is changed, or "Use Selection" reassigns it.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np
from mathutils import Vector

from lipgen.blender import ForceResponses
from lipgen.errors import LipgenError

from . import bridge, lipobject

__all__ = ["update", "update_settings", "force_displacement", "drop_sessions", "local_direction"]


@dataclass
class _Session:
    fingerprint: str
    responses: ForceResponses


_SESSIONS: dict[int, _Session] = {}


def drop_sessions(obj=None) -> None:
    """Forget the preview state of ``obj`` (or of every object)."""
    if obj is None:
        _SESSIONS.clear()
    else:
        _SESSIONS.pop(obj.session_uid, None)


def _fingerprint(obj) -> str:
    s = obj.lipgen
    me = obj.data
    h = hashlib.sha1(bridge.rest_vertices(obj).tobytes())
    h.update(repr((len(me.vertices), len(me.polygons), len(me.loops), s.unit_mm, s.poisson,
                   s.stiffness_lip, s.stiffness_ridge, s.stiffness_strip, s.stiffness_skin,
                   s.anchors_group, s.force_group)).encode())
    return h.hexdigest()


def local_direction(obj, world_direction) -> np.ndarray:
    """A world-space direction in the object's own coordinates (unit length)."""
    d = obj.matrix_world.to_3x3().inverted_safe() @ Vector(world_direction)
    if d.length == 0.0:
        raise lipobject.UserError("the force direction is zero; set a direction")
    return np.array(d.normalized(), dtype=np.float64)


def _responses(obj, group: str, reuse: bool) -> ForceResponses:
    fp = _fingerprint(obj)
    sess = _SESSIONS.get(obj.session_uid)
    if reuse and sess is not None and sess.fingerprint == fp:
        return sess.responses
    if not group or obj.vertex_groups.get(group) is None:
        raise lipobject.UserError(f"no vertex group {group!r}: select vertices in Edit Mode and "
                                  "press Use Selection, or pick a group")
    nodes = bridge.vertex_group_nodes(obj, group)
    if len(nodes) == 0:
        raise lipobject.UserError(f"the vertex group {group!r} is empty; assign the vertices to push")
    spec = lipobject.physics_spec(obj)
    phys = lipobject.physics_for_object(obj, spec)
    resp = ForceResponses(phys, nodes, phys.mesh.vertex_normals())
    _SESSIONS[obj.session_uid] = _Session(fp, resp)
    return resp


def force_displacement(obj, group: str, magnitude: float, use_normal: bool,
                       world_direction=(0.0, 0.0, 1.0), reuse: bool = True,
                       peak: bool = False) -> np.ndarray:
    """(n, 3) displacement in mm of ``magnitude`` per vertex of ``group``.

    Along each vertex normal if ``use_normal``, else along ``world_direction``. With ``peak``
    the magnitude is the largest vertex displacement in mm instead of the force.
    """
    resp = _responses(obj, group, reuse)
    direction = None if use_normal else local_direction(obj, world_direction)
    return resp.displacement(magnitude, direction, peak=peak)


def _apply(settings, reuse: bool) -> None:
    obj = settings.id_data
    if not settings.force_preview:
        if bridge.remove_shape_key(obj, lipobject.PREVIEW_KEY):
            obj.data.update()
        settings.force_status = ""
        return
    if obj.mode != "OBJECT":
        settings.force_status = "Preview pauses in Edit Mode"
        return
    try:
        U = force_displacement(obj, settings.force_group, settings.force_magnitude,
                               settings.force_use_normal, settings.force_direction, reuse=reuse,
                               peak=settings.force_units == "PEAK")
        lipobject.write_displacement_key(obj, lipobject.PREVIEW_KEY, U, 1.0)
        settings.force_status = f"peak {np.linalg.norm(U, axis=1).max():.3g} mm"
    except (lipobject.UserError, LipgenError, ValueError) as exc:
        settings.force_status = str(exc)


def update(settings, context) -> None:
    """Update callback of magnitude and direction: reuse the stored responses."""
    _apply(settings, reuse=True)


def update_settings(settings, context) -> None:
    """Update callback of the preview switch, vertex group and normal choice: re-read them."""
    drop_sessions(settings.id_data)
    _apply(settings, reuse=False)
