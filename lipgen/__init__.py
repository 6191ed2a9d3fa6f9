"""lipgen: a physically based 3D lip model (Basu 1997) and tools around it.

The package reads like the data flow; each stage uses only the stages above it in this list:

* :mod:`lipgen.mesh` - the lip mesh; :mod:`lipgen.fem` - its physics;
  :mod:`lipgen.modes` - learned modes, LLSE
* :mod:`lipgen.usd` - USD export; :mod:`lipgen.rig` - cameras, mirror rig, scene, renderer
* :mod:`lipgen.subject` - the synthetic subject; :mod:`lipgen.dataset` - datasets on disk
* :mod:`lipgen.recon` - reconstruction from frames; :mod:`lipgen.nrsfm` - non-rigid SfM
* :mod:`lipgen.evaluate` - scores against the truth; :mod:`lipgen.blender` - the add-on's data side
* :mod:`lipgen.campaign` - many datasets through the stages on Ray, one aggregated report
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
from lipgen.tol import tol

__version__ = "0.1.0"
"""The package version (PEP 440)."""

_compat.install()

_SUBPACKAGES = ("mesh", "fem", "modes", "usd", "rig", "subject", "dataset", "recon", "nrsfm", "evaluate",
                "campaign", "blender", "experiments", "bench", "commands")


_LAZY = {"DEFAULT_STIFFNESS": "lipgen.fem", "Physics": "lipgen.fem", "dofs": "lipgen.fem",
         "LipMesh": "lipgen.mesh", "lip_mesh": "lipgen.mesh",
         "LLSE": "lipgen.modes", "ModeModel": "lipgen.modes", "llse": "lipgen.modes"}
"""Top-level names imported on first use: ``import lipgen`` (and so every CLI start) must not
pay for scipy and the physics (about 1 s) before it knows it needs them."""


def __getattr__(name: str):
    # ``lipgen.usd``, ``lipgen.nrsfm`` ... without importing every stage up front
    if name in _SUBPACKAGES:
        return _importlib.import_module(f"lipgen.{name}")
    if name in _LAZY:
        value = getattr(_importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'lipgen' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY) | set(_SUBPACKAGES))

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
