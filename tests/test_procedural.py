"""The default procedural lips: counts, symmetry, nesting, topology, regions, markers, anchors.

Each property is checked against an independent reference (graph distances, trimesh's own
topology, brute-force closest points, plain geometry), not against the builder's bookkeeping.
"""

from collections import deque

import numpy as np
import pytest
import trimesh

import lipgen
from lipgen.mesh.procedural import MARKER_NAMES, lip_mesh, mirror_permutation, thesis_unit_mm

FLIP = np.array([-1.0, 1.0, 1.0])


@pytest.fixture(scope="module")
def meshes():
    return [lip_mesh(r) for r in range(4)]


def test_exported_and_thesis_sized(meshes):
    assert lipgen.lip_mesh is lip_mesh
    m = meshes[0]
    assert abs(m.n_nodes - 204) <= 0.1 * 204 and abs(m.n_faces - 336) <= 0.1 * 336
    for a, b in zip(meshes, meshes[1:], strict=False):
        assert b.n_faces == 4 * a.n_faces
        assert 3.5 < b.n_nodes / a.n_nodes < 4.0


def test_bad_resolution():
    with pytest.raises(ValueError, match="resolution must be in"):
        lip_mesh(-1)
    with pytest.raises(TypeError, match="integer"):
        lip_mesh(1.5)


def _face_set(faces):
    return {tuple(np.roll(f, -int(np.argmin(f)))) for f in faces.tolist()}  # cyclic order kept


@pytest.mark.parametrize("r", [0, 2])
def test_mirror_symmetry(meshes, r):
    m = meshes[r]
    V = m.vertices
    # independent pairing: sort both point sets the same way
    a = np.lexsort(np.round(V, 9).T[::-1])
    b = np.lexsort(np.round(V * FLIP, 9).T[::-1])
    assert np.allclose(V[a], (V * FLIP)[b], atol=1e-9)
    perm = mirror_permutation(m)
    assert np.allclose(V[perm], V * FLIP, atol=1e-9) and np.array_equal(perm[perm], np.arange(m.n_nodes))
    # reflection reverses orientation: mirrored faces, reversed, are faces with the same region
    mirrored = perm[m.faces][:, ::-1]
    assert _face_set(mirrored) == _face_set(m.faces)
    region_of = dict(zip(_face_set_list(m.faces), m.regions.tolist(), strict=True))
    mirrored_regions = [region_of[f] for f in _face_set_list(mirrored)]
    assert mirrored_regions == m.regions.tolist()
    assert set(perm[m.anchors].tolist()) == set(m.anchors.tolist())
    for name in m.marker_names:
        twin = name.replace("left", "@").replace("right", "left").replace("@", "right")
        assert perm[m.marker_index(name)] == m.marker_index(twin)


def _face_set_list(faces):
    return [tuple(np.roll(f, -int(np.argmin(f)))) for f in faces.tolist()]


def test_asymmetric_mesh_is_refused():
    m = lip_mesh(0)
    V = m.vertices.copy()
    V[5, 0] += 0.3
    with pytest.raises(lipgen.MeshError, match="not symmetric"):
        mirror_permutation(m.with_vertices(V))


def test_nested_resolutions(meshes):
    for a, b in zip(meshes, meshes[1:], strict=False):
        assert np.allclose(b.vertices[: a.n_nodes], a.vertices, atol=1e-9)
        assert np.array_equal(a.markers, b.markers) and a.marker_names == b.marker_names
        assert np.allclose(a.marker_positions, b.marker_positions, atol=1e-9)
        assert set(a.anchors.tolist()) <= set(b.anchors.tolist())
        assert np.array_equal(a.nose, b.nose)
        for reg in a.region_names:  # the same part of the surface keeps its region
            assert b.region_mask(reg).sum() == 4 * a.region_mask(reg).sum()


def test_refinement_converges_to_one_smooth_surface(meshes):
    """Finer nodes lie on the coarser mesh up to O(h^2): the gap shrinks ~4x per step."""
    rng = np.random.default_rng(0)
    gaps = []
    for r in (0, 1):
        pts = meshes[r + 1].vertices
        pts = pts[rng.choice(len(pts), size=min(len(pts), 400), replace=False)]
        _, d, _ = trimesh.proximity.closest_point_naive(meshes[r].to_trimesh(), pts)
        gaps.append(np.percentile(d, 95))
    assert gaps[0] < 1.0 and gaps[1] < gaps[0] / 2.5


@pytest.mark.parametrize("r", [0, 1, 3])
def test_manifold_consistently_oriented_outward(meshes, r):
    m = meshes[r]
    tm = m.to_trimesh()
    directed = m.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    assert len(np.unique(directed, axis=0)) == len(directed)  # no directed edge twice: consistent
    _, count = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    assert count.max() == 2  # every edge in one or two faces
    assert tm.is_winding_consistent and tm.body_count == 1
    assert tm.euler_number == 0  # an annulus: the outer border and the mouth opening
    nz = m.face_normals()[:, 2]
    outer = ~m.region_mask("strip")
    assert (nz[outer] > 0.1).all()  # the outer surface faces the viewer (the ridge rolls inwards)
    assert (nz[m.region_mask("lip")] > 0.5).all()
    assert (nz[m.region_mask("strip")] < 0).all()  # the strip faces into the mouth
    ang = np.degrees(tm.face_angles).min()
    assert ang > 8.0  # well-shaped elements, not degrading with refinement


def _graph_distance(faces, n, sources):
    adj = [[] for _ in range(n)]
    for a, b in faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2).tolist():
        adj[a].append(b)
        adj[b].append(a)
    dist = np.full(n, -1)
    dist[sources] = 0
    q = deque(sources.tolist())
    while q:
        u = q.popleft()
        for v in adj[u]:
            if dist[v] < 0:
                dist[v] = dist[u] + 1
                q.append(v)
    return dist


def _outer_border(m):
    """Nodes of the boundary loop that holds the mesh's rightmost node (the skin's outer border)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    edges, count = np.unique(np.sort(m.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0,
                             return_counts=True)
    b = edges[count == 1]
    g = coo_matrix((np.ones(len(b)), (b[:, 0], b[:, 1])), shape=(m.n_nodes, m.n_nodes))
    _, label = connected_components(g, directed=False)
    nodes = np.unique(b)
    return nodes[label[nodes] == label[np.argmax(m.vertices[:, 0])]]


def _rigid_rank(P):
    """Rank of the six rigid motions (3 translations, 3 small rotations) sampled at points P."""
    cols = [np.tile(e, len(P)) for e in np.eye(3)] + [np.cross(e, P).ravel() for e in np.eye(3)]
    return np.linalg.matrix_rank(np.stack(cols, 1), tol=1e-6 * np.abs(P).max())


@pytest.mark.parametrize("r", [0, 2])
def test_regions_and_anchors(meshes, r):
    m = meshes[r]
    for reg in ("lip", "ridge", "strip", "skin"):
        assert m.region_mask(reg).any()
    strip_only = np.setdiff1d(m.region_nodes("strip"), np.concatenate(
        [m.region_nodes(g) for g in ("lip", "ridge", "skin")]))
    attached = np.intersect1d(m.region_nodes("strip"), m.region_nodes("ridge"))
    dist = _graph_distance(m.faces, m.n_nodes, attached)
    far = strip_only[dist[strip_only] == dist[strip_only].max()]
    border = _outer_border(m)
    assert (m.vertices[border, 2] < 0).all() and len(border) == 24 * 2**r
    assert np.array_equal(m.anchors, np.union1d(far, border))
    thesis = lip_mesh(r, anchor_border=False)
    assert np.array_equal(thesis.anchors, far) and np.array_equal(thesis.vertices, m.vertices)
    # either set grounds all six rigid motions (the far end alone is not collinear) and the
    # surface is one piece, so the grounded stiffness can be positive definite
    assert _rigid_rank(m.vertices[far]) == 6 and _rigid_rank(m.vertices[m.anchors]) == 6
    assert m.to_trimesh().body_count == 1


def test_markers_on_visible_lip(meshes):
    m = meshes[0]
    assert m.marker_names == MARKER_NAMES and len(MARKER_NAMES) == 16
    lip = set(m.region_nodes("lip").tolist())
    strip = set(m.region_nodes("strip").tolist())
    for name, node in zip(m.marker_names, m.markers.tolist(), strict=True):
        assert node in lip and node not in strip and node not in set(m.anchors.tolist()), name
    assert (m.vertex_normals()[m.markers, 2] > 0.3).all()
    first8 = m.marker_positions[:8]
    assert np.ptp(first8[:, 0]) > 45 and np.ptp(first8[:, 1]) > 12  # spread round the mouth


def test_plausible_human_lips(meshes):
    m = meshes[1]
    P = dict(zip(m.marker_names, m.marker_positions, strict=True))
    width = P["corner_left"][0] - P["corner_right"][0]
    assert 45 < width < 58 and P["corner_left"][0] > 0  # +x is the subject's left
    assert P["bow_peak_left"][1] > P["bow_dip"][1] > P["upper_mid"][1] > 0 > P["lower_mid"][1]
    assert 6 < P["bow_dip"][1] - 1.5 < 10 and 7 < -P["lower_border_mid"][1] - 1.5 < 12  # vermilion
    assert P["upper_mid"][2] - P["corner_left"][2] > 6  # corners recede, lips protrude
    lips = m.vertices[m.region_nodes("lip")]
    assert m.nose[1] > lips[:, 1].max() + 10 and m.nose[2] > lips[:, 2].max() and m.nose[0] == 0
    inner = m.vertices[m.region_nodes("ridge")]
    assert np.abs(inner.mean(0)[[0]]).max() < 1e-9  # centred on the midline


def test_thesis_units(meshes):
    u = thesis_unit_mm(meshes[0])
    assert np.isclose(u, np.ptp(meshes[0].vertices[:, 0]) / 2.83)
    assert np.isclose(thesis_unit_mm(), u) and np.isclose(thesis_unit_mm(meshes[2]), u)
    assert abs(np.ptp(meshes[0].vertices[:, 1]) / u - 2.35) < 0.05  # height matches "across"


def test_grounded_stiffness_positive_definite_and_border_helps():
    from lipgen.fem import Physics

    conds = []
    for border in (True, False):
        w = np.linalg.eigvalsh(Physics(lip_mesh(0, anchor_border=border)).K_s.toarray())
        assert w[0] > 1e-8 * w[-1]
        conds.append(w[-1] / w[0])
    assert conds[0] < conds[1] / 3  # the skin border removes the soft swinging modes


def test_bench_suite_quick():
    from lipgen.bench import mesh as suite

    out = suite.run(quick=True)
    assert [row["nodes"] for row in out["levels"]] == [lip_mesh(r).n_nodes for r in range(3)]
    assert all(row["build_s"] > 0 and row["validate_s"] > 0 for row in out["levels"])
