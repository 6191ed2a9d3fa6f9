"""One shared set of numerical tolerances (as ``trimesh.tol``).

Lengths are in millimetres, so absolute tolerances are in mm (or mm^2 for areas).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Tolerance", "tol"]


@dataclass(frozen=True)
class Tolerance:
    """Numerical tolerances, one place for all of lipgen (use :data:`tol`)."""

    zero: float = 1e-12
    """Values below this are treated as exactly zero."""
    area: float = 1e-10
    """Faces with an area below this (mm^2) are degenerate."""
    merge: float = 1e-8
    """Vertices closer than this (mm) are the same point."""
    rank: float = 1e-10
    """Relative singular-value cutoff for pseudo-inverses and rank decisions."""
    solve: float = 1e-10
    """Relative residual a direct solve must reach."""


tol = Tolerance()
"""The one tolerance object of lipgen (see :class:`Tolerance`)."""
