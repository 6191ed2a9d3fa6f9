"""What every LipGen operator shares: the poll, error reporting, and undo."""

from __future__ import annotations

import logging

import bpy

from lipgen.errors import LipgenError

from .lipobject import UserError

log = logging.getLogger("lipgen.blender")

# Errors an artist can act on: shown in the status bar, never a traceback. LipgenError covers
# MeshError, SingularStiffnessError, TopologyMismatchError and ModelFileError.
USER_ERRORS = (UserError, LipgenError, ValueError, OSError, KeyError)


class LipgenOperator:
    """Mixin: ``REGISTER`` + ``UNDO``, a mesh-object poll, and errors reported, not raised.

    Subclasses implement ``run(context)``. It must check everything before it changes Blender
    data, so a refused operation leaves the scene as it was.
    """

    bl_options = {"REGISTER", "UNDO"}
    needs_mesh = True

    @classmethod
    def poll(cls, context):
        if not cls.needs_mesh:
            return context.mode == "OBJECT" or context.mode.startswith("EDIT")
        ob = context.active_object
        return ob is not None and ob.type == "MESH"

    def execute(self, context):
        try:
            result = self.run(context)
        except USER_ERRORS as exc:
            self.report({"ERROR"}, str(exc))
            log.info("%s refused: %s", self.bl_idname, exc)
            return {"CANCELLED"}
        return result or {"FINISHED"}

    def run(self, context):  # pragma: no cover - every operator overrides it
        raise UserError(f"{type(self).__name__} does nothing")


def active_mesh(context):
    """The active mesh object, in Object Mode.

    Edit Mode keeps its own copy of the mesh: leaving it first puts the artist's edits (moved
    vertices, selection) into the mesh data, and keeps what the operator writes from being
    overwritten when Edit Mode ends.
    """
    obj = context.active_object
    if obj is None or obj.type != "MESH":
        raise UserError("select a mesh object first")
    if obj.mode != "OBJECT":
        bpy.ops.object.mode_set(mode="OBJECT")
    return obj


def lipgen_object(context):
    """:func:`active_mesh`, which must be set up for LipGen."""
    obj = active_mesh(context)
    if not obj.lipgen.enabled:
        raise UserError(f"{obj.name!r} is not set up for LipGen: add LipGen lips, or press "
                        "Set Up Physics for your own mesh")
    return obj
