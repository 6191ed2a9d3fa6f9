"""LipMesh validates itself and round-trips through its file format."""

import numpy as np
import pytest

from lipgen import MeshError, ModelFileError
from lipgen.mesh.lipmesh import LipMesh


def square():
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    return V, F


def test_valid_mesh_is_readonly_and_hashes_topology():
    V, F = square()
    m = LipMesh(V, F, anchors=[0, 1], markers=[2], marker_names=("tip",))
    assert m.n_nodes == 4 and m.n_dofs == 12 and m.marker_index("tip") == 2
    with pytest.raises(ValueError):
        m.vertices[0, 0] = 5.0
    assert m.with_vertices(V + 1).topology_id == m.topology_id
    assert LipMesh(V, F[:, [0, 2, 1]], anchors=[0]).topology_id != m.topology_id
    assert np.allclose(m.face_normals(), [0, 0, 1])


@pytest.mark.parametrize("faces, match", [
    ([[0, 1, 1], [0, 2, 3]], "repeat a node"),
    ([[0, 1, 2], [0, 2, 3], [2, 1, 0]], "duplicate face"),
    ([[0, 1, 9]], "outside"),
    ([[0, 1, 2]], "belong to no face"),
])
def test_bad_faces_are_named(faces, match):
    V, _ = square()
    with pytest.raises(MeshError, match=match):
        LipMesh(V, np.array(faces), anchors=[0])


def test_zero_area_face():
    V = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]], float)
    with pytest.raises(MeshError, match="zero-area"):
        LipMesh(V, np.array([[0, 1, 2], [0, 1, 3]]))


def test_bad_indices_and_shapes():
    V, F = square()
    with pytest.raises(ValueError, match="anchors has 1 index"):
        LipMesh(V, F, anchors=[0, 4])
    with pytest.raises(ValueError, match="marker_names has 2 names for 1"):
        LipMesh(V, F, markers=[1], marker_names=("a", "b"))
    with pytest.raises(ValueError, match=r"vertices must have shape \(\*, 3\)"):
        LipMesh(V[:, :2], F)
    with pytest.raises(ValueError, match="regions must have shape"):
        LipMesh(V, F, regions=[0])


def test_save_load_roundtrip_and_corruption(tmp_path):
    V, F = square()
    m = LipMesh(V, F, regions=[0, 2], anchors=[0], markers=[3, 2], marker_names=("a", "b"), nose=[0, 2, 1])
    p = tmp_path / "m.npz"
    m.save(p)
    m2 = LipMesh.load(p)
    assert m2.topology_id == m.topology_id and m2.marker_names == ("a", "b")
    assert np.array_equal(m2.regions, m.regions) and np.array_equal(m2.nose, m.nose)
    p.write_bytes(p.read_bytes()[:50])
    with pytest.raises(ModelFileError):
        LipMesh.load(p)


def test_from_file_keeps_vertex_order(tmp_path):
    V, F = square()
    p = tmp_path / "sq.obj"
    p.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in V) + "".join(
        f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F))
    m = LipMesh.from_file(p, anchors=[0], regions={"ridge": [1]})
    assert np.allclose(m.vertices, V) and m.region_names[m.regions[1]] == "ridge"
