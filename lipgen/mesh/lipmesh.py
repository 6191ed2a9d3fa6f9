"""The lip mesh: geometry, per-face regions, anchors, markers and the nose reference.

:class:`LipMesh` is an immutable record that validates itself on construction, so every
other module can trust it. The procedural default lips are built by
:func:`lipgen.mesh.procedural.lip_mesh`; an artist's own mesh is loaded with
:meth:`LipMesh.from_file` (OBJ, PLY, STL through trimesh) or built from plain arrays.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from lipgen._io import load_npz, save_npz
from lipgen._validate import as_float_array, as_index_array
from lipgen.errors import MeshError
from lipgen.tol import tol

__all__ = ["LipMesh", "REGIONS", "merge_coincident_vertices"]

REGIONS: tuple[str, ...] = ("lip", "ridge", "strip", "skin")
"""Default region names: lip surface, inner ridge along the lip contour, the low-stiffness strip
back into the oral cavity, and the skin around the lips."""

_KIND, _SCHEMA = "lipgen.LipMesh", 1


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class LipMesh:
    """A triangle mesh with what the physics and the reconstruction need to know about it.

    Parameters
    ----------
    vertices : (n, 3) float
        Node positions in millimetres, model frame (+x subject's left, +y up, +z out of the face).
    faces : (m, 3) int
        Triangles as node indices, counter-clockwise seen from outside (normals point out).
    regions : (m,) int, optional
        Region code of each face, an index into ``region_names``. Defaults to all ``"lip"``.
    anchors : (a,) int
        Nodes fixed to the head (grounded in the physics).
    markers : (k,) int, optional
        Marker nodes, in the order of ``marker_names``.
    marker_names : tuple of str, optional
        One name per marker. Defaults to ``("m0", "m1", ...)``.
    nose : (3,) float, optional
        A point fixed to the head (the nose mark), in mm. Defaults to the origin.
    region_names : tuple of str
        Names of the region codes.
    name : str
        A label for messages and files.
    """

    vertices: np.ndarray
    faces: np.ndarray
    regions: np.ndarray | None = None
    anchors: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    markers: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    marker_names: tuple[str, ...] | None = None
    nose: np.ndarray | None = None
    region_names: tuple[str, ...] = REGIONS
    name: str = "lips"

    def __post_init__(self) -> None:
        V = as_float_array(self.vertices, "vertices", (None, 3))
        n = len(V)
        if n < 3:
            raise MeshError(f"a mesh needs at least 3 vertices, got {n}")
        F = np.asarray(self.faces)
        if F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
            raise MeshError(f"faces must have shape (m, 3) with m >= 1, got {F.shape}")
        if not np.issubdtype(F.dtype, np.integer):
            raise TypeError(f"faces must hold integer node indices, got dtype {F.dtype}")
        F = F.astype(np.int64)
        bad = (F < 0) | (F >= n)
        if bad.any():
            i = int(np.argwhere(bad)[0, 0])
            raise MeshError(f"face {i} {F[i].tolist()} refers to a node outside [0, {n})")
        _check_faces(V, F)
        names = tuple(str(s) for s in self.region_names)
        if len(set(names)) != len(names) or not names:
            raise ValueError(f"region_names must be distinct and non-empty, got {names}")
        R = np.zeros(len(F), np.int64) if self.regions is None else np.asarray(self.regions)
        if R.shape != (len(F),):
            raise ValueError(f"regions must have shape ({len(F)},) (one per face), got {R.shape}")
        R = as_index_array(R, "regions", len(names))
        A = as_index_array(self.anchors, "anchors", n, unique=True)
        M = as_index_array(self.markers, "markers", n, unique=True)
        mnames = tuple(f"m{i}" for i in range(len(M))) if self.marker_names is None else tuple(
            str(s) for s in self.marker_names)
        if len(mnames) != len(M):
            raise ValueError(f"marker_names has {len(mnames)} names for {len(M)} markers")
        if len(set(mnames)) != len(mnames):
            raise ValueError(f"marker_names must be distinct, got {mnames}")
        nose = np.zeros(3) if self.nose is None else as_float_array(self.nose, "nose", (3,))
        object.__setattr__(self, "vertices", _readonly(V))
        object.__setattr__(self, "faces", _readonly(F))
        object.__setattr__(self, "regions", _readonly(R))
        object.__setattr__(self, "anchors", _readonly(A))
        object.__setattr__(self, "markers", _readonly(M))
        object.__setattr__(self, "marker_names", mnames)
        object.__setattr__(self, "nose", _readonly(nose))
        object.__setattr__(self, "region_names", names)

    # ---- sizes and identity -------------------------------------------------------------
    @property
    def n_nodes(self) -> int:
        return len(self.vertices)

    @property
    def n_faces(self) -> int:
        return len(self.faces)

    @property
    def n_dofs(self) -> int:
        """Degrees of freedom, three per node, node-major ``(x0, y0, z0, x1, ...)``."""
        return 3 * len(self.vertices)

    @property
    def topology_id(self) -> str:
        """A short hash of the node count and the faces: equal for meshes that share topology.

        Models, datasets and Blender objects record it to refuse a mesh they were not built for.
        """
        h = hashlib.sha1(np.int64(self.n_nodes).tobytes())
        h.update(np.ascontiguousarray(self.faces, dtype="<i8").tobytes())
        return h.hexdigest()[:16]

    # ---- queries -------------------------------------------------------------------------
    def region_mask(self, region: str) -> np.ndarray:
        """(m,) bool: faces in ``region``."""
        if region not in self.region_names:
            raise ValueError(f"unknown region {region!r}; this mesh has {self.region_names}")
        return self.regions == self.region_names.index(region)

    def region_nodes(self, region: str) -> np.ndarray:
        """Sorted node indices touched by faces of ``region``."""
        return np.unique(self.faces[self.region_mask(region)])

    def marker_index(self, name: str) -> int:
        """Node index of the marker called ``name``."""
        try:
            return int(self.markers[self.marker_names.index(name)])
        except ValueError:
            raise ValueError(f"unknown marker {name!r}; markers are {self.marker_names}") from None

    @property
    def marker_positions(self) -> np.ndarray:
        """(k, 3) rest positions of the markers, in marker order."""
        return self.vertices[self.markers]

    def face_normals(self) -> np.ndarray:
        """(m, 3) unit face normals (right-hand rule over each face's node order)."""
        tri = self.vertices[self.faces]
        nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        return nrm / np.linalg.norm(nrm, axis=1, keepdims=True)

    def vertex_normals(self) -> np.ndarray:
        """(n, 3) unit vertex normals, area-weighted over adjacent faces."""
        tri = self.vertices[self.faces]
        nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        out = np.zeros_like(self.vertices)
        for k in range(3):
            np.add.at(out, self.faces[:, k], nrm)
        return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), tol.zero)

    def with_vertices(self, vertices) -> LipMesh:
        """The same mesh (topology, regions, anchors, markers) at new vertex positions."""
        return replace(self, vertices=vertices)

    def to_trimesh(self):
        """A :class:`trimesh.Trimesh` of the geometry (no processing, same vertex order)."""
        import trimesh

        return trimesh.Trimesh(self.vertices.copy(), self.faces.copy(), process=False)

    # ---- files ---------------------------------------------------------------------------
    def save(self, path: str | os.PathLike) -> None:
        """Write to ``.npz`` (schema-versioned, atomic)."""
        save_npz(path, _KIND, _SCHEMA, {
            "vertices": self.vertices, "faces": self.faces, "regions": self.regions,
            "anchors": self.anchors, "markers": self.markers,
            "marker_names": np.array(self.marker_names, dtype=str),
            "nose": self.nose, "region_names": np.array(self.region_names, dtype=str),
            "name": np.array(self.name),
        })

    @classmethod
    def load(cls, path: str | os.PathLike) -> LipMesh:
        """Read a file written by :meth:`save`."""
        d = load_npz(path, _KIND, _SCHEMA, required=(
            "vertices", "faces", "regions", "anchors", "markers", "marker_names", "nose",
            "region_names"))
        return cls(d["vertices"], d["faces"], d["regions"], d["anchors"], d["markers"],
                   tuple(d["marker_names"].tolist()), d["nose"], tuple(d["region_names"].tolist()),
                   str(d.get("name", "lips")))

    @classmethod
    def from_file(cls, path: str | os.PathLike, anchors, markers=(), marker_names=None,
                  regions=None, region_names: tuple[str, ...] = REGIONS, nose=None) -> LipMesh:
        """Load a user's triangle mesh (OBJ, PLY, STL, ... through trimesh).

        ``anchors`` and ``markers`` are node indices into the file's vertices; ``regions`` is
        either one code per face or a mapping ``{region name: face indices}`` (faces not listed
        are ``"lip"``). Polygons are split into triangles (fans, in file order).

        Vertex order is the file's own for OBJ (also when texture seams would otherwise split
        vertices) and PLY. STL stores every triangle with its own three corners and no shared
        vertices, so coincident corners (bit-identical coordinates, as STL writers produce) are
        merged; the nodes are then numbered in order of first appearance in the file's
        triangles, and ``anchors``/``markers`` refer to that numbering.
        """
        import trimesh

        p = Path(path)
        if not p.is_file():
            raise FileNotFoundError(f"no such mesh file: {p}")
        kind = p.suffix.lower().lstrip(".")
        kwargs = {"maintain_order": True} if kind == "obj" else {}
        try:
            tm = trimesh.load(p, process=False, force="mesh", **kwargs)
        except Exception as exc:  # trimesh raises many types for unreadable files
            raise MeshError(f"could not read {p} as a triangle mesh ({exc}); lipgen reads OBJ, PLY "
                            "and STL files of triangles or polygons") from exc
        if not isinstance(tm, trimesh.Trimesh) or len(tm.faces) == 0:
            raise MeshError(f"{p} holds no triangles (is it empty, a point cloud, or not a mesh?)")
        V, F = np.asarray(tm.vertices, float), np.asarray(tm.faces, np.int64)
        if kind == "stl":
            V, F = merge_coincident_vertices(V, F)
        if isinstance(regions, dict):
            codes = np.full(len(F), region_names.index("lip") if "lip" in region_names else 0)
            for rname, idx in regions.items():
                if rname not in region_names:
                    raise ValueError(f"unknown region {rname!r}; known: {region_names}")
                codes[as_index_array(idx, f"regions[{rname!r}]", len(F))] = region_names.index(rname)
            regions = codes
        return cls(V, F, regions, anchors, markers, marker_names, nose, region_names, name=p.stem)


def merge_coincident_vertices(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices with identical coordinates (e.g. the corners of STL triangles).

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int

    Returns
    -------
    vertices : (k, 3) float
        The distinct points, in order of first appearance in ``vertices``.
    faces : (m, 3) int
        ``faces`` re-indexed into them.
    """
    uniq, first, inverse = np.unique(vertices, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    new_id = np.empty(len(order), np.int64)
    new_id[order] = np.arange(len(order))
    return uniq[order], new_id[inverse.reshape(-1)][faces]


def _check_faces(V: np.ndarray, F: np.ndarray) -> None:
    """Raise :class:`MeshError` for repeated nodes in a face, zero-area, duplicate faces, or
    nodes that belong to no face."""
    rep = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])
    if rep.any():
        i = int(np.flatnonzero(rep)[0])
        raise MeshError(f"{int(rep.sum())} face(s) repeat a node, e.g. face {i} = {F[i].tolist()}")
    tri = V[F]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    scale = max(float(np.ptp(V, axis=0).max()), 1.0)
    small = area <= tol.area * scale**2
    if small.any():
        i = int(np.flatnonzero(small)[0])
        raise MeshError(
            f"{int(small.sum())} degenerate (zero-area) face(s), e.g. face {i} = {F[i].tolist()} "
            f"with area {area[i]:.3g} mm^2; remove or re-triangulate them")
    key = np.sort(F, axis=1)
    _, first, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    if (counts > 1).any():
        i = int(first[np.flatnonzero(counts > 1)[0]])
        raise MeshError(f"{int((counts > 1).sum())} duplicate face(s), e.g. {F[i].tolist()}")
    used = np.zeros(len(V), bool)
    used[F.ravel()] = True
    if not used.all():
        loose = np.flatnonzero(~used)
        raise MeshError(
            f"{len(loose)} vertex(es) belong to no face, e.g. {loose[:5].tolist()}; remove them "
            "(trimesh: mesh.remove_unreferenced_vertices()) and re-index anchors and markers")
