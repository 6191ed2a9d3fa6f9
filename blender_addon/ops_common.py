"""What every LipGen operator shares: the poll, error reporting, and undo."""

from __future__ import annotations

import logging

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
