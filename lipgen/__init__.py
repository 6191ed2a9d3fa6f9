"""lipgen: a physically based 3D lip model (Basu 1997) and tools around it.

The package reads like the data flow; each stage uses only the stages above it in this list:

* :mod:`lipgen.mesh` - the lip mesh; :mod:`lipgen.fem` - its physics;
  :mod:`lipgen.modes` - learned modes, LLSE
* :mod:`lipgen.usd` - USD export; :mod:`lipgen.rig` - cameras, mirror rig, scene, renderer
* :mod:`lipgen.subject` - the synthetic subject; :mod:`lipgen.dataset` - datasets on disk
* :mod:`lipgen.recon` - reconstruction from frames; :mod:`lipgen.nrsfm` - non-rigid SfM
* :mod:`lipgen.evaluate` - scores against the truth; :mod:`lipgen.blender` - the add-on's data side
* :mod:`lipgen.experiments`, :mod:`lipgen.bench`, :mod:`lipgen.commands` - the thesis's experiments,
  benchmarks and the command line
"""

from __future__ import annotations

import importlib as _importlib

from lipgen import _compat
from lipgen.errors import (
    DatasetError,
    LipgenError,
    MeshError,
    MissingDependencyError,
    ModelFileError,
    RenderBackendError,
    SingularStiffnessError,
    TopologyMismatchError,
)
from lipgen.fem import DEFAULT_STIFFNESS, Physics, dofs
from lipgen.mesh import LipMesh, lip_mesh
from lipgen.modes import LLSE, ModeModel, llse
from lipgen.tol import tol

__version__ = "0.1.0"
"""The package version (PEP 440)."""

_compat.install()

_SUBPACKAGES = ("mesh", "fem", "modes", "usd", "rig", "subject", "dataset", "recon", "nrsfm", "evaluate",
                "blender", "experiments", "bench", "commands")


def __getattr__(name: str):
    # ``lipgen.usd``, ``lipgen.nrsfm`` ... without importing every stage up front
    if name in _SUBPACKAGES:
        return _importlib.import_module(f"lipgen.{name}")
    raise AttributeError(f"module 'lipgen' has no attribute {name!r}")

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
