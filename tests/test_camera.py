"""Pinhole cameras, the camera-mirror rig and ray-midpoint triangulation.

Projections are checked against OpenCV's ``projectPoints`` (an independent implementation);
the mirror against the reflection written out by hand; triangulation against closed forms.
"""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lipgen.rig.camera import (
    VIEWS,
    MirrorRig,
    PinholeCamera,
    default_rig,
    look_at_rotation,
    rig_from_eyes,
    triangulate,
    triangulate_rays,
)

cv2 = pytest.importorskip("cv2")


def _random_camera(rng, dist=None, width=640, height=480):
    R = Rotation.from_rotvec(rng.normal(size=3) * 0.5).as_matrix()
    K = np.array([[rng.uniform(400, 900), 0, rng.uniform(250, 390)],
                  [0, rng.uniform(400, 900), rng.uniform(180, 300)], [0, 0, 1]])
    return PinholeCamera(K, R, rng.normal(size=3) * 20, width, height, dist)


def _points_in_front(cam, rng, n=200):
    """World points spread over the camera's field of view, 150-600 mm deep."""
    uv = rng.uniform([0, 0], [cam.width - 1, cam.height - 1], size=(n, 2))
    o, d = cam.rays(uv)
    depth = rng.uniform(150, 600, size=(n, 1))
    return o + d * depth / (d @ cam.R[2])[:, None]


def _face_cloud():
    """Lips, jaw drop and nose: a box of points around the mouth (mm, model frame)."""
    g = np.stack(np.meshgrid(np.linspace(-30, 30, 7), np.linspace(-35, 18, 6), np.linspace(-8, 10, 3)),
                 -1).reshape(-1, 3)
    return np.vstack([g, [[0, 36, 22], [-12, 28, 12], [12, 28, 12]]])


@pytest.mark.parametrize("dist", [None, (-0.12, 0.05), (0.08, -0.02, 0.01)])
def test_projection_matches_opencv(dist):
    rng = np.random.default_rng(1)
    for _ in range(5):
        cam = _random_camera(rng, dist)
        X = _points_in_front(cam, rng)
        rvec, _ = cv2.Rodrigues(cam.R)
        ref, _ = cv2.projectPoints(X, rvec, cam.t, cam.K, cam.opencv_dist())
        uv, depth = cam.project(X, return_depth=True)
        np.testing.assert_allclose(uv, ref[:, 0], atol=1e-8)
        np.testing.assert_allclose(depth, (X @ cam.R.T + cam.t)[:, 2])


@pytest.mark.parametrize("dist", [None, (-0.12, 0.05, 0.002)])
def test_rays_invert_projection(dist):
    rng = np.random.default_rng(2)
    cam = _random_camera(rng, dist)
    uv = rng.uniform([-0.5, -0.5], [cam.width - 0.5, cam.height - 0.5], size=(300, 2))
    o, d = cam.rays(uv)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0)
    np.testing.assert_allclose(o, np.broadcast_to(cam.center, o.shape))
    np.testing.assert_allclose(cam.project(o + 250 * d), uv, atol=1e-9)


def test_camera_centre_and_look_at():
    eye, target = np.array([100.0, 20, 300]), np.array([0.0, 5, 0])
    cam = PinholeCamera.look_at(eye, target, 640, 480, 600.0)
    np.testing.assert_allclose(cam.center, eye, atol=1e-12)
    np.testing.assert_allclose(cam.project(target[None]), [[319.5, 239.5]], atol=1e-9)
    above = cam.project(target[None] + [0, 10, 0])[0]
    assert above[1] < 239.5, "world up must appear up in the image (smaller v)"
    assert np.linalg.det(look_at_rotation(eye, target)) == pytest.approx(1.0)


def test_behind_camera_and_outside_image_are_not_in_view():
    cam = PinholeCamera.look_at([0, 0, 300.0], [0, 0, 0], 64, 48, 60.0)
    X = np.array([[0, 0, 0], [0, 0, 400.0], [1000, 0, 0], [0, 0, 300.0]])
    uv = cam.project(X)
    assert np.isfinite(uv[0]).all() and np.isnan(uv[1]).all() and np.isnan(uv[3]).all()
    assert cam.in_view(X).tolist() == [True, False, False, False]
    # pixel (0, 0) is the centre of the top-left pixel: the image spans [-0.5, W - 0.5]
    assert cam.inside(np.array([[-0.5, -0.5], [63.5, 47.5], [-0.51, 0], [0, 47.51]])).tolist() == [
        True, True, False, False]


def test_scaled_camera_keeps_pixel_centre_convention():
    rng = np.random.default_rng(3)
    cam = _random_camera(rng, (-0.1, 0.02))
    X = _points_in_front(cam, rng, 50)
    small = cam.scaled(160, 120)
    np.testing.assert_allclose(small.project(X), (cam.project(X) + 0.5) / 4 - 0.5, atol=1e-9)


def test_triangulate_rays_closed_form():
    # x axis, and a line along y through (3, 0, 2): closest points (3,0,0) and (3,0,2)
    p, gap = triangulate_rays([0, 0, 0], [1, 0, 0], [3, -5, 2], [0, 2, 0])
    np.testing.assert_allclose(p, [3, 0, 1], atol=1e-12)
    assert gap == pytest.approx(2.0)
    p, gap = triangulate_rays([[0, 0, 0]], [[1, 0, 0]], [[0, 1, 0]], [[1, 0, 0]])
    assert np.isnan(p).all() and np.isnan(gap).all(), "parallel rays have no unique closest point"


@pytest.mark.parametrize("dist", [None, (-0.08, 0.03)])
def test_triangulating_exact_projections_recovers_points(dist):
    rng = np.random.default_rng(4)
    base = default_rig()
    rig = MirrorRig(PinholeCamera(base.camera.K, base.camera.R, base.camera.t, 640, 480, dist),
                    base.mirror_normal, base.mirror_offset)
    X = _face_cloud() + rng.normal(size=(len(_face_cloud()), 3))
    uv, _, inside = rig.project(X)
    assert inside.all()
    P, gap = rig.triangulate(uv[VIEWS.index("real")], uv[VIEWS.index("virtual")])
    np.testing.assert_allclose(P, X, atol=1e-9)
    assert gap.max() < 1e-9
    P2, _ = triangulate(rig.camera, rig.camera.project(X), rig.virtual, rig.virtual.project(X))
    np.testing.assert_allclose(P2, X, atol=1e-9)


def test_mirror_consistency():
    rig = default_rig()
    rng = np.random.default_rng(5)
    X = _face_cloud() + rng.normal(size=(len(_face_cloud()), 3))
    W = rig.camera.width
    # written out by hand: reflection in the plane n.X = d
    n, d = rig.mirror_normal, rig.mirror_offset
    Xr = X - 2 * ((X @ n) - d)[:, None] * n
    np.testing.assert_allclose(rig.reflect(X), Xr, atol=1e-12)
    # the real camera sees the reflection where the (proper) virtual camera sees the point, flipped
    u_real = rig.camera.project(Xr)
    u_virt = rig.virtual.project(X)
    np.testing.assert_allclose(u_virt[:, 0], W - 1 - u_real[:, 0], atol=1e-9)
    np.testing.assert_allclose(u_virt[:, 1], u_real[:, 1], atol=1e-9)
    # and symmetrically, the point seen directly lands where the virtual camera sees its reflection
    np.testing.assert_allclose(rig.virtual.project(Xr)[:, 0], W - 1 - rig.camera.project(X)[:, 0], atol=1e-9)
    assert np.linalg.det(rig.virtual.R) == pytest.approx(1.0)
    np.testing.assert_allclose(rig.virtual.center, rig.reflect(rig.camera.center), atol=1e-9)
    assert rig.virtual_flip == "horizontal"


@pytest.mark.parametrize("side", ["left", "right"])
def test_split_views_puts_points_where_the_view_cameras_project(side):
    base = default_rig(320, 240)
    if side == "right":  # the default rig mirrored left-right: camera on the subject's right
        flip = np.array([-1.0, 1, 1])
        base = rig_from_eyes(base.camera.center * flip, base.virtual.center * flip, [0, 5, 0], 320, 240,
                             mirror_side="right")
    X = _face_cloud()
    uv, _, inside = base.project(X)
    assert inside.all()
    raw = np.zeros((240, 320), np.int32)
    # paint each point's direct image and its mirror image into the raw frame, as the camera sees them
    direct = np.round(base.camera.project(X)).astype(int)
    mirrored = np.round(base.camera.project(base.reflect(X))).astype(int)
    raw[direct[:, 1], direct[:, 0]] = 1
    raw[mirrored[:, 1], mirrored[:, 0]] = 2
    virt, real = base.split_views(raw)
    for img, k, label in ((virt, VIEWS.index("virtual"), 2), (real, VIEWS.index("real"), 1)):
        px = np.round(uv[k]).astype(int)
        assert (img[px[:, 1], px[:, 0]] == label).all()
    np.testing.assert_array_equal(base.compose(virt, real), raw)
    np.testing.assert_allclose(base.to_raw("real", uv[1]), base.camera.project(X), atol=1e-9)
    np.testing.assert_allclose(base.to_raw("virtual", uv[0]), base.camera.project(base.reflect(X)), atol=1e-9)


def test_default_rig_sees_face_over_head_motion():
    rig = default_rig()
    X = _face_cloud()
    pivot = np.array([0, 0, -90.0])
    for rotvec in np.radians([[10, 0, 0], [-10, 0, 0], [0, 10, 0], [0, -10, 0], [0, 0, 10], [7, 7, 7]]):
        R = Rotation.from_rotvec(rotvec).as_matrix()
        for t in ([10, 0, 0], [-10, 0, 0], [0, 10, 0], [0, -10, 0], [0, 0, 10], [0, 0, -10]):
            rig.check_sees((X - pivot) @ R.T + pivot + t, margin=5)


def test_rig_round_trips_through_dict():
    rig = default_rig()
    back = MirrorRig.from_dict(rig.to_dict())
    X = _face_cloud()
    np.testing.assert_allclose(back.project(X)[0], rig.project(X)[0], atol=1e-9)
    assert back.to_dict() == rig.to_dict()


def test_bad_rigs_are_refused_with_clear_errors():
    rig = default_rig()
    face = _face_cloud()
    cam = rig.camera
    raised = PinholeCamera(cam.K, cam.R, -cam.R @ (cam.center + [0, 600, 0]), 640, 480)
    with pytest.raises(ValueError, match="sees nothing"):
        MirrorRig(raised, rig.mirror_normal, rig.mirror_offset).check_sees(face)
    away = look_at_rotation(cam.center, 2 * cam.center)
    with pytest.raises(ValueError, match="does not look at the mirror"):
        MirrorRig(PinholeCamera(cam.K, away, -away @ cam.center, 640, 480), rig.mirror_normal,
                  rig.mirror_offset)
    # the mirror moved across the face: the face is behind it
    with pytest.raises(ValueError, match="does not show the face.*behind"):
        MirrorRig(cam, rig.mirror_normal, rig.mirror_normal @ [5.0, 0, 0]).check_sees(face)
    # the mirror moved far away: the reflection leaves the mirror half
    with pytest.raises(ValueError, match="does not show the face.*mirror"):
        MirrorRig(cam, rig.mirror_normal, rig.mirror_offset - 150).check_sees(face)
    with pytest.raises(ValueError, match="not inside the direct"):
        rig.check_sees(face + [-110, 0, 0])
    with pytest.raises(ValueError, match="lies on the mirror plane"):
        MirrorRig(cam, rig.mirror_normal, rig.mirror_normal @ cam.center)
    with pytest.raises(ValueError, match="zero vector"):
        MirrorRig(cam, [0, 0, 0], 1.0)
    with pytest.raises(ValueError, match="raw frame must have shape"):
        rig.split_views(np.zeros((480, 600, 3)))


def test_bad_cameras_are_refused():
    K = np.array([[500.0, 0, 319.5], [0, 500, 239.5], [0, 0, 1]])
    with pytest.raises(ValueError, match="determinant -1"):
        PinholeCamera(K, np.diag([1.0, 1, -1]), np.zeros(3), 640, 480)
    with pytest.raises(ValueError, match="not a rotation"):
        PinholeCamera(K, np.eye(3) * 1.1, np.zeros(3), 640, 480)
    with pytest.raises(ValueError, match="skew"):
        PinholeCamera(K + [[0, 1, 0], [0, 0, 0], [0, 0, 0]], np.eye(3), np.zeros(3), 640, 480)
    with pytest.raises(ValueError, match="positive"):
        PinholeCamera(K * [[-1], [1], [1]], np.eye(3), np.zeros(3), 640, 480)
    with pytest.raises(ValueError, match="width"):
        PinholeCamera(K, np.eye(3), np.zeros(3), 0, 480)
    with pytest.raises(ValueError, match="folds the image"):
        PinholeCamera(K, np.eye(3), np.zeros(3), 640, 480, (-0.9, 0.0))
    with pytest.raises(ValueError, match="shape"):
        PinholeCamera(K, np.eye(3), np.zeros(2), 640, 480)
    with pytest.raises(ValueError, match="convention"):
        PinholeCamera.from_dict({**PinholeCamera(K, np.eye(3), np.zeros(3), 640, 480).to_dict(),
                                 "convention": "opengl"})
