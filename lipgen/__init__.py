"""lipgen: a physically based 3D lip model (Basu 1997) and tools around it."""

from __future__ import annotations

__version__ = "0.1.0"

from .errors import (
    DatasetError,
    LipgenError,
    MeshError,
    MissingDependencyError,
    ModelFileError,
    RenderBackendError,
    SingularStiffnessError,
    TopologyMismatchError,
)
from .fem import DEFAULT_STIFFNESS, Physics, dofs
from .llse import LLSE, llse
from .mesh import LipMesh
from .modes import ModeModel
from .procedural import lip_mesh
from .tol import tol

__all__ = [
    "__version__",
    "tol",
    "LipMesh",
    "lip_mesh",
    "LipgenError",
    "MeshError",
    "SingularStiffnessError",
    "ModelFileError",
    "TopologyMismatchError",
    "DatasetError",
    "RenderBackendError",
    "MissingDependencyError",
    "ModeModel",
    "LLSE",
    "llse",
    "Physics",
    "DEFAULT_STIFFNESS",
    "dofs",
]
