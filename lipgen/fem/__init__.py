"""Thin-shell finite-element physics of the lips (Basu 1997, ch. 2, §4.1, App. A).

* :mod:`~lipgen.fem.element`: the triangle's stiffness (eqs 2.9-2.14), vectorised over faces.
* :mod:`~lipgen.fem.assembly`: per-face E, sparse global K, grounding checks.
* :mod:`~lipgen.fem.solver`: the sparse factorisation of K_s (CHOLMOD or SuperLU).
* :mod:`~lipgen.fem.physics`: :class:`Physics` (``displace``, ``reach``, ``relinearized``).
* :mod:`~lipgen.fem.planar`: the planar-mesh demonstration of the thesis's Fig 2-2.
"""

from lipgen.fem.assembly import DEFAULT_STIFFNESS, assemble_stiffness, check_grounding, face_stiffness
from lipgen.fem.element import OUT_OF_PLANE, element_stiffness
from lipgen.fem.physics import Physics, dofs
from lipgen.fem.solver import SOLVERS, cholmod_available

__all__ = [
    "DEFAULT_STIFFNESS",
    "OUT_OF_PLANE",
    "SOLVERS",
    "Physics",
    "assemble_stiffness",
    "check_grounding",
    "cholmod_available",
    "dofs",
    "element_stiffness",
    "face_stiffness",
]
