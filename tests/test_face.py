"""The rendered subject's geometry (no OpenGL): face proxy seam, ink dots, visibility ray casts."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lipgen.mesh.procedural import lip_mesh
from lipgen.rig.camera import PinholeCamera, default_rig
from lipgen.rig.scene import vertex_normals
from lipgen.rig.visibility import occluded, segment_hits
from lipgen.subject.decal import make_decal, place_decal
from lipgen.subject.face import FaceLook, FaceModel, boundary_loops


@pytest.fixture(scope="module")
def face():
    return FaceModel(lip_mesh(0))


def _pose(rotvec, t):
    P = np.eye(4)
    P[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    P[:3, 3] = t
    return P


def test_boundary_loops_of_a_grid():
    n = 5
    idx = np.arange(n * n).reshape(n, n)
    quads = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], -1).reshape(-1, 4)
    faces = np.vstack([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    loops = boundary_loops(faces)
    assert len(loops) == 1 and len(loops[0]) == 4 * (n - 1)
    loop = loops[0]
    edges = {tuple(sorted(e)) for f in faces for e in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0]))}
    assert all(tuple(sorted((a, b))) in edges for a, b in zip(loop, np.roll(loop, -1), strict=True))


def test_proxy_closes_the_lip_border_watertight(face):
    mesh = face.mesh
    lowest = int(np.argmin(mesh.vertices[:, 1]))  # the chin end of the skin is on the outer border
    outer = next(lp for lp in boundary_loops(mesh.faces) if lowest in lp)
    assert set(face.loop.tolist()) == set(outer.tolist())
    # the lip border is no longer a boundary of the combined face surface
    remaining = set(np.concatenate(boundary_loops(face.faces)).tolist())
    assert not remaining & set(face.loop.tolist())
    # proxy faces look out of the face (towards +z) nearly everywhere in front
    V = face.surfaces(mesh.vertices)["face"][0]
    tri = V[face.proxy_faces]
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    front = np.abs(tri.mean(axis=1)[:, 0]) < 40
    assert (nrm[front, 2] > 0).mean() > 0.95


def test_proxy_follows_the_border_and_the_head(face):
    mesh = face.mesh
    U = np.zeros_like(mesh.vertices)
    U[:, 1] = -0.2 * np.clip(-mesh.vertices[:, 1], 0, None)  # the lower face drops
    V = mesh.vertices + U
    pose = _pose([0.05, -0.08, 0.02], [3.0, -2.0, 1.0])
    Vf = face.surfaces(V, pose)["face"][0]
    R, t = pose[:3, :3], pose[:3, 3]
    np.testing.assert_allclose(Vf[: mesh.n_nodes], V @ R.T + t, atol=1e-12)
    # the proxy's outermost ring stays put (relative to the head), the rest of the seam is shared
    outer_ring = Vf[-len(face.loop):]
    np.testing.assert_allclose(outer_ring, face.proxy_rest[-len(face.loop):] @ R.T + t, atol=1e-9)


def test_nose_tip_is_the_nose_point_and_marks_move_with_the_head(face):
    mesh = face.mesh
    pose = _pose([0.02, 0.1, -0.03], [1.0, 2.0, -3.0])
    surf = face.surfaces(mesh.vertices, pose)
    P, N = face.marks(mesh.vertices, pose)
    R, t = pose[:3, :3], pose[:3, 3]
    np.testing.assert_allclose(P[-1], R @ mesh.nose + t, atol=1e-9)
    np.testing.assert_allclose(surf["nose"][0][0], P[-1], atol=1e-9)
    np.testing.assert_allclose(P[:-1], mesh.marker_positions @ R.T + t, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1.0)
    assert (N[:, 2] > 0).all(), "marks face the front"


def test_decal_centre_is_the_marker_and_hugs_the_deformed_surface(face):
    mesh = face.mesh
    V0 = face.surfaces(mesh.vertices)["face"][0]
    N0 = vertex_normals(V0, face.faces)
    k = mesh.marker_index("upper_left")
    d = make_decal(V0, face.faces, N0, k, 1.0)
    assert len(d.bary) > 40 and np.allclose(d.bary.sum(axis=1), 1.0)
    # a smooth non-rigid deformation: the dot centre stays on the marked vertex
    V = V0 + np.stack([0.1 * V0[:, 1], 0.05 * V0[:, 0] ** 2 / 30, 0.02 * V0[:, 0]], 1)
    N = vertex_normals(V, face.faces)
    P = place_decal(d, V, face.faces, N, lift=0.0)
    np.testing.assert_allclose(P[0], V[k], atol=1e-9)
    # every decal vertex lies on its triangle's plane (lift 0) and within reach of the centre
    tri = V[face.faces[d.face]]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    assert np.abs(np.sum((P - tri[:, 0]) * n, axis=1)).max() < 1e-9
    assert np.linalg.norm(P - P[0], axis=1).max() < 1.6
    lifted = place_decal(d, V, face.faces, N, lift=0.05)
    assert np.abs(np.linalg.norm(lifted - P, axis=1) - 0.05).max() < 1e-9


def test_every_marker_gets_a_whole_dot(face):
    for d in face.marker_decals + [face.nose_decal]:
        assert len(d.rim) >= 12 and len(d.faces) >= 60


def test_segment_hits_closed_form():
    tri = np.array([[[-1.0, -1, 0], [1, -1, 0], [0, 1, 0]]])
    o = np.array([[0.0, 0, 5]])
    assert segment_hits(o, np.array([[0.0, 0, -5]]), tri)[0]
    assert not segment_hits(o, np.array([[0.0, 0, 1]]), tri)[0], "target in front of the triangle"
    assert not segment_hits(o, np.array([[0.0, 0, 0]]), tri)[0], "a point on the surface does not hide itself"
    assert not segment_hits(o, np.array([[3.0, 0, -5]]), tri)[0], "passes beside it"


def test_occluded_matches_brute_force():
    rng = np.random.default_rng(0)
    cam = PinholeCamera.look_at([0, 0, 300.0], [0, 0, 0], 160, 120, 200.0)
    centers = rng.uniform([-40, -30, -20], [40, 30, 20], size=(400, 3))
    tris = centers[:, None, :] + rng.normal(size=(400, 3, 3)) * 4
    pts = rng.uniform([-40, -30, -25], [40, 30, 25], size=(300, 3))
    got = occluded(cam, pts, tris)
    o = np.broadcast_to(cam.center, (len(pts), 3))
    brute = np.array([segment_hits(np.repeat(o[i:i + 1], len(tris), 0), np.repeat(pts[i:i + 1], len(tris), 0),
                                   tris).any() for i in range(len(pts))])
    inside = cam.in_view(pts)
    np.testing.assert_array_equal(got[inside], brute[inside])
    assert brute[inside].any() and not brute[inside].all()


def test_default_rig_sees_every_mark_of_the_default_lips(face):
    rig = default_rig()
    surf = face.surfaces(face.mesh.vertices)
    P, N = face.marks(face.mesh.vertices)
    tris = face.occluders(surf)
    for cam in rig.views:
        assert cam.in_view(P, margin=20).all()
        assert not occluded(cam, P, tris).any()
        assert (np.sum((cam.center - P) * N, axis=1) > 0).all()


def test_bad_look_is_refused():
    with pytest.raises(ValueError, match="dot_diameter"):
        FaceLook(dot_diameter=0.0)
    with pytest.raises(ValueError, match="vertices must have shape"):
        FaceModel(lip_mesh(0)).surfaces(np.zeros((10, 3)))
