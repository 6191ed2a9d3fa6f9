"""The lip mesh: :class:`LipMesh`, the procedural lips, mesh files, and pictures.

* :mod:`~lipgen.mesh.lipmesh`: :class:`LipMesh` (vertices, faces, regions, anchors, markers, nose).
* :mod:`~lipgen.mesh.procedural`: :func:`lip_mesh`, the thesis-like lips at any resolution.
* :mod:`~lipgen.mesh.io`: an artist's OBJ/PLY/STL (+ sidecar) in and out.
* :mod:`~lipgen.mesh.plot`: pictures of a mesh and its regions (imports matplotlib when used).
"""

from lipgen.mesh.io import MESH_SUFFIXES, read_mesh, sidecar_path, write_mesh
from lipgen.mesh.lipmesh import REGIONS, LipMesh, merge_coincident_vertices
from lipgen.mesh.procedural import (
    MARKER_NAMES,
    NOSE,
    THESIS_EXTENT_UNITS,
    lip_mesh,
    mirror_permutation,
    thesis_unit_mm,
)

__all__ = [
    "LipMesh", "REGIONS", "merge_coincident_vertices", "lip_mesh", "MARKER_NAMES", "NOSE",
    "THESIS_EXTENT_UNITS", "mirror_permutation", "thesis_unit_mm", "MESH_SUFFIXES", "read_mesh",
    "sidecar_path", "write_mesh",
]
