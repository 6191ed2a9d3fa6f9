"""Loading users' meshes (OBJ, PLY, STL, arrays), writing ours with a sidecar, and `lipgen mesh`."""

import json

import numpy as np
import pytest
import trimesh

from lipgen import MeshError
from lipgen.cli import main
from lipgen.mesh.io import read_mesh, sidecar_path, write_mesh
from lipgen.mesh.lipmesh import LipMesh, merge_coincident_vertices
from lipgen.mesh.procedural import lip_mesh


@pytest.fixture(scope="module")
def lips():
    return lip_mesh(0)


def _same_mesh(a, b, atol=0.0):
    assert np.allclose(a.vertices, b.vertices, atol=atol, rtol=0)
    assert np.array_equal(a.faces, b.faces) and np.array_equal(a.regions, b.regions)
    assert np.array_equal(a.anchors, b.anchors) and np.array_equal(a.markers, b.markers)
    assert a.marker_names == b.marker_names and np.allclose(a.nose, b.nose)


def test_obj_keeps_vertex_order_across_uv_seams(tmp_path):
    # a quad with a texture seam at vertex 1: trimesh would split it unless told to keep order
    p = tmp_path / "seam.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvt .5 .5\n"
                 "vn 0 0 1\nf 1/1/1 2/2/1 3/3/1\nf 1/5/1 3/3/1 4/4/1\n")
    m = LipMesh.from_file(p, anchors=[0, 1, 3], markers=[2], marker_names=("tip",))
    assert m.n_nodes == 4 and np.array_equal(m.faces, [[0, 1, 2], [0, 2, 3]])
    assert np.allclose(m.marker_positions, [[1, 1, 0]])
    q = tmp_path / "quad.obj"  # polygons are split into triangles
    q.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    assert LipMesh.from_file(q, anchors=[0]).n_faces == 2


def test_ply_from_other_writers(tmp_path, lips):
    tm = trimesh.Trimesh(lips.vertices, lips.faces, process=False)
    for enc in ("binary", "ascii"):
        p = tmp_path / f"l_{enc}.ply"
        p.write_bytes(trimesh.exchange.ply.export_ply(tm, encoding=enc))
        m = LipMesh.from_file(p, anchors=lips.anchors, markers=lips.markers, regions=lips.regions)
        assert np.array_equal(m.faces, lips.faces)
        assert np.allclose(m.vertices, lips.vertices, atol=1e-4)  # trimesh writes float32


def test_stl_merges_corners_in_order_of_appearance(tmp_path, lips):
    tm = trimesh.Trimesh(lips.vertices, lips.faces, process=False)
    for enc in ("stl", "stl_ascii"):
        p = tmp_path / f"l.{enc}.stl"
        tm.export(p, file_type=enc)
        m = LipMesh.from_file(p, anchors=[0, 1, 2])
        assert (m.n_nodes, m.n_faces) == (lips.n_nodes, lips.n_faces)
        # reference numbering: first appearance while walking the triangles in file order
        seen = {}
        for v in lips.faces.ravel().tolist():
            seen.setdefault(v, len(seen))
        old_of_new = np.array(sorted(seen, key=seen.get))
        assert np.allclose(m.vertices, lips.vertices[old_of_new], atol=1e-4)
        assert np.array_equal(old_of_new[m.faces], lips.faces)


def test_merge_coincident_vertices_reference():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    W, F = merge_coincident_vertices(V, np.array([[0, 1, 2], [3, 4, 5]]))
    assert np.array_equal(W, [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    assert np.array_equal(F, [[0, 1, 2], [1, 3, 2]])


def test_plain_arrays(lips):
    m = LipMesh(lips.vertices.tolist(), lips.faces.tolist(), lips.regions.tolist(), lips.anchors.tolist(),
                lips.markers.tolist(), list(lips.marker_names), lips.nose.tolist())
    _same_mesh(m, lips)
    assert m.topology_id == lips.topology_id


@pytest.mark.parametrize("content, match", [
    (b"", "no triangles"),
    (b"this is not a mesh\n", "no triangles"),
    (b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no triangles"),
    (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n", "could not read|outside"),
])
def test_bad_obj_files(tmp_path, content, match):
    p = tmp_path / "bad.obj"
    p.write_bytes(content)
    with pytest.raises(MeshError, match=match):
        LipMesh.from_file(p, anchors=[0])


def test_bad_files_other_formats(tmp_path):
    p = tmp_path / "bad.stl"
    p.write_bytes(b"\x00" * 40)
    with pytest.raises(MeshError, match="could not read|no triangles"):
        LipMesh.from_file(p, anchors=[0])
    q = tmp_path / "mesh.xyz"
    q.write_text("1 2 3\n")
    with pytest.raises(MeshError, match="could not read"):
        LipMesh.from_file(q, anchors=[0])
    with pytest.raises(FileNotFoundError, match="no such mesh file"):
        LipMesh.from_file(tmp_path / "missing.obj", anchors=[0])


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".npz"])
def test_write_read_roundtrip(tmp_path, lips, suffix):
    p = tmp_path / f"lips{suffix}"
    written = write_mesh(lips, p)
    assert p in written and (suffix == ".npz") == (sidecar_path(p) not in written)
    _same_mesh(read_mesh(p), lips)
    # independent reader: trimesh sees the same geometry in the same order
    if suffix != ".npz":
        tm = trimesh.load(p, process=False, force="mesh", maintain_order=True)
        assert np.allclose(tm.vertices, lips.vertices) and np.array_equal(tm.faces, lips.faces)
    with pytest.raises(FileExistsError):
        write_mesh(lips, p)


def test_write_refuses_stl_and_checks_sidecar(tmp_path, lips):
    with pytest.raises(ValueError, match="STL stores no shared vertices"):
        write_mesh(lips, tmp_path / "l.stl")
    p = tmp_path / "l.obj"
    write_mesh(lips, p)
    meta = json.loads(sidecar_path(p).read_text())
    meta["n_nodes"] += 1
    sidecar_path(p).write_text(json.dumps(meta))
    with pytest.raises(MeshError, match="edited after export"):
        read_mesh(p)
    sidecar_path(p).unlink()
    with pytest.raises(MeshError, match="no sidecar"):
        read_mesh(p)


def test_cli_mesh(tmp_path, capsys):
    out, png = tmp_path / "lips.ply", tmp_path / "lips.png"
    assert main(["mesh", "-r", "1", "--out", str(out), "--plot", str(png), "--views", "front"]) == 0
    text = capsys.readouterr().out
    assert "750 nodes" in text and "upper_mid" in text and png.stat().st_size > 10_000
    assert read_mesh(out).n_nodes == 750
    assert main(["mesh", "--from", str(out)]) == 0 and "750 nodes" in capsys.readouterr().out
    assert main(["mesh", "--out", str(out)]) == 1  # never overwrites silently
    assert "--force" in capsys.readouterr().err
    assert main(["mesh", "--plot", str(tmp_path / "x.png"), "--views", "top"]) == 1
