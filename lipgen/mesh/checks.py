"""Checks of an artist's mesh before it is trusted: its size against a human mouth (units), and
cracks (coincident vertices that faces do not share, split seams, non-manifold fin edges), with
a weld that closes them.

A crack is not an error the element sees: each side is a valid surface, so the mesh builds, and
then tears open under force (the sides move apart). Coincident vertices are found within a
distance (default :attr:`lipgen.tol.weld`, mm); edges used by more than two faces are fins.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lipgen._validate import as_float_array, as_index_array
from lipgen.tol import tol

__all__ = ["MOUTH_WIDTH_MM", "MESH_WIDTH_MM", "UNITS_MM", "UnitCheck", "check_units", "Cracks",
           "find_cracks", "weld", "anchor_warning"]

MOUTH_WIDTH_MM = (40.0, 70.0)
"""Width of a human mouth, corner to corner (mm)."""
MESH_WIDTH_MM = (25.0, 250.0)
"""Plausible largest extent of a lip mesh: a small mouth alone up to a mouth with the skin of the
lower face around it (the default lips are 72 mm wide)."""
UNITS_MM = {"mm": 1.0, "cm": 10.0, "in": 25.4, "dm": 100.0, "m": 1000.0}
"""Candidate units of a file's numbers, in mm."""


@dataclass(frozen=True)
class UnitCheck:
    """The result of :func:`check_units`.

    Attributes: ``width_mm`` (largest extent at the given unit), ``ok``, ``likely_unit`` (name
    in :data:`UNITS_MM`, or None), ``suggested_unit_mm`` (mm per mesh unit that would make it
    mouth-sized, or None) and ``message`` (empty when ``ok``).
    """

    width_mm: float
    ok: bool
    likely_unit: str | None
    suggested_unit_mm: float | None
    message: str


def check_units(vertices, unit_mm: float = 1.0) -> UnitCheck:
    """Compare a mesh's size with a human mouth and name the likely unit of its numbers.

    Parameters
    ----------
    vertices : (n, 3) float
        The mesh's coordinates, in its own units.
    unit_mm : float
        Millimetres per mesh unit as currently set up (1 for a millimetre mesh).
    """
    V = as_float_array(vertices, "vertices", (None, 3))
    unit_mm = float(unit_mm)
    if not np.isfinite(unit_mm) or unit_mm <= 0:
        raise ValueError(f"unit_mm must be a positive number, got {unit_mm}")
    extent = float(np.ptp(V, axis=0).max()) if len(V) else 0.0
    width = extent * unit_mm
    lo, hi = MESH_WIDTH_MM
    if lo <= width <= hi:
        return UnitCheck(width, True, None, None, "")
    target = np.sqrt(MOUTH_WIDTH_MM[0] * MOUTH_WIDTH_MM[1])
    fits = {name: u for name, u in UNITS_MM.items() if lo <= extent * u <= hi}
    name = min(fits, key=lambda k: abs(np.log(extent * fits[k] / target))) if fits and extent > 0 else None
    msg = (f"the mesh is {width:.4g} mm wide at {unit_mm:g} mm per unit; a human mouth is about "
           f"{MOUTH_WIDTH_MM[0]:g}-{MOUTH_WIDTH_MM[1]:g} mm wide ({lo:g}-{hi:g} mm with the skin around it)")
    if name is not None:
        msg += (f". Its numbers look like {name}: set {UNITS_MM[name]:g} mm per unit (in Blender: "
                f"scale the object by {UNITS_MM[name] / unit_mm:g} and apply the scale)")
    else:
        msg += "; rescale it to millimetres"
    return UnitCheck(width, False, name, UNITS_MM[name] if name else None, msg)


@dataclass(frozen=True)
class Cracks:
    """What :func:`find_cracks` found.

    Attributes
    ----------
    pairs : (k, 2) int
        Distinct vertices, both used by faces, closer than the distance (duplicates, split seams).
    fins : (e, 2) int
        Edges (sorted node pairs) used by more than two faces (non-manifold).
    distance : float
    """

    pairs: np.ndarray
    fins: np.ndarray
    distance: float

    @property
    def ok(self) -> bool:
        """True when nothing was found."""
        return len(self.pairs) == 0 and len(self.fins) == 0

    @property
    def vertices(self) -> np.ndarray:
        """(v,) every vertex involved, sorted."""
        return np.unique(np.concatenate([self.pairs.ravel(), self.fins.ravel()]))

    @property
    def message(self) -> str:
        """What was found, the vertices or edges named, and the fix (empty when ``ok``)."""
        parts = []
        if len(self.pairs):
            shown = ", ".join(f"{a}={b}" for a, b in self.pairs[:6].tolist())
            parts.append(f"{len(self.pairs)} pair(s) of coincident vertices not shared by their faces "
                         f"(a crack or split seam that tears under force): {shown}"
                         + (" ..." if len(self.pairs) > 6 else "")
                         + f"; weld them (distance {self.distance:g} mm)")
        if len(self.fins):
            shown = ", ".join(f"{a}-{b}" for a, b in self.fins[:6].tolist())
            parts.append(f"{len(self.fins)} non-manifold edge(s) used by more than two faces (fins): {shown}"
                         + (" ..." if len(self.fins) > 6 else "") + "; delete the extra faces")
        return "; ".join(parts)


def find_cracks(vertices, faces, distance: float | None = None) -> Cracks:
    """Coincident vertices that faces do not share, and non-manifold edges.

    Parameters
    ----------
    vertices : (n, 3) float
        Millimetres.
    faces : (m, 3) int
    distance : float, optional
        Vertices closer than this (mm) are the same point; default :attr:`lipgen.tol.weld`.
    """
    from scipy.spatial import cKDTree

    V = as_float_array(vertices, "vertices", (None, 3))
    F = np.asarray(faces)
    if F.ndim != 2 or F.shape[1] != 3:
        raise ValueError(f"faces must have shape (m, 3), got {F.shape}")
    F = as_index_array(F.ravel(), "faces", len(V)).reshape(-1, 3)
    dist = tol.weld if distance is None else float(distance)
    if not np.isfinite(dist) or dist < 0:
        raise ValueError(f"distance must be a non-negative number of mm, got {distance!r}")
    used = np.zeros(len(V), bool)
    used[F.ravel()] = True
    idx = np.flatnonzero(used)
    pairs = cKDTree(V[idx]).query_pairs(dist, output_type="ndarray") if len(idx) else np.zeros((0, 2), int)
    pairs = np.sort(idx[pairs], axis=1) if len(pairs) else np.zeros((0, 2), np.int64)
    pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))] if len(pairs) else pairs
    edges = np.sort(F[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    uniq, counts = np.unique(edges, axis=0, return_counts=True)
    return Cracks(pairs.astype(np.int64), uniq[counts > 2].astype(np.int64), dist)


def weld(vertices, faces, distance: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Merge vertices closer than ``distance`` (mm) into one (the lowest index of each cluster).

    Returns
    -------
    vertices : (k, 3) float
        The kept vertices, in their original order.
    faces : (m', 3) int
        Re-indexed; faces that collapse (two corners welded together) are dropped.
    old_to_new : (n,) int
        New index of every old vertex: remap anchors and markers with it.
    """
    V = as_float_array(vertices, "vertices", (None, 3))
    F = np.asarray(faces)
    cracks = find_cracks(V, F, distance)
    parent = np.arange(len(V))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in cracks.pairs:
        ra, rb = root(a), root(b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    rep = np.array([root(i) for i in range(len(V))])
    keep = np.flatnonzero(rep == np.arange(len(V)))
    new_of_keep = np.full(len(V), -1)
    new_of_keep[keep] = np.arange(len(keep))
    old_to_new = new_of_keep[rep]
    G = old_to_new[np.asarray(F, np.int64)]
    ok = (G[:, 0] != G[:, 1]) & (G[:, 1] != G[:, 2]) & (G[:, 0] != G[:, 2])
    return V[keep], G[ok], old_to_new


def anchor_warning(vertices, anchors) -> str:
    """A warning (empty if none) when the anchors do not hold the mesh firmly: fewer than three,
    or all on one line. Such a mesh can turn about the line and is held only by the element's
    out-of-plane term (eq 2.13), a weak, artificial restraint."""
    V = as_float_array(vertices, "vertices", (None, 3))
    a = as_index_array(anchors, "anchors", len(V))
    if len(a) == 0:
        return "no anchors: choose the vertices fixed to the head (e.g. the far edge of the strip)"
    P = V[a] - V[a].mean(axis=0)
    sv = np.linalg.svd(P, compute_uv=False) if len(a) > 1 else np.zeros(1)
    if len(a) < 3 or len(sv) < 2 or sv[1] <= 1e-6 * max(sv[0], tol.zero):
        return (f"only {len(a)} anchor(s)" if len(a) < 3 else f"the {len(a)} anchors lie on one line") + (
            ": the mesh can turn about them and is held only weakly; anchor at least three vertices "
            "not on one line (the far edge of the strip into the mouth)")
    return ""
