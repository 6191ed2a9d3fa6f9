"""Exception types.

Bad values raise ``ValueError`` / ``TypeError`` naming the value and its shape. Where the
domain explains a failure better than a bare shape check, a :class:`LipgenError` subclass is
raised instead; every subclass also derives from the built-in it refines, so callers may catch
either.
"""

from __future__ import annotations

__all__ = [
    "LipgenError",
    "MeshError",
    "SingularStiffnessError",
    "ModelFileError",
    "TopologyMismatchError",
    "DatasetError",
    "RenderBackendError",
    "MissingDependencyError",
]


class LipgenError(Exception):
    """Base class for lipgen's domain errors."""


class MeshError(LipgenError, ValueError):
    """A mesh the element cannot handle (degenerate or duplicate faces, bad indices, ...)."""


class SingularStiffnessError(LipgenError, ValueError):
    """The grounded stiffness is singular: too few anchors, or parts of the mesh not attached."""


class ModelFileError(LipgenError, ValueError):
    """A saved file that is corrupt, of another kind, or of an unsupported schema version."""


class TopologyMismatchError(LipgenError, ValueError):
    """A model or dataset built for one mesh topology was applied to another."""


class DatasetError(LipgenError, ValueError):
    """A dataset folder that is missing, incomplete or inconsistent."""


class RenderBackendError(LipgenError, RuntimeError):
    """No usable OpenGL backend for offscreen rendering."""


class MissingDependencyError(LipgenError, ImportError):
    """An optional dependency is not installed."""
