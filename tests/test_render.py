"""Offscreen rendering through the rig: rendered ink dots land on the truth projections.

The centroid of each rendered dot is measured from the image alone: the frame is rendered
with and without the dots, and the darkening (as a fraction of full ink coverage) weights
the pixels. The label render only separates dots that touch. Truth projections come from
:class:`MirrorRig` and visibility from exact ray casting, independent of the rasteriser.
"""

import os
import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lipgen.mesh.procedural import lip_mesh
from lipgen.rig.camera import MirrorRig, PinholeCamera, default_rig
from lipgen.rig.scene import Scene
from lipgen.rig.visibility import occluded
from lipgen.subject.face import FaceModel

pytestmark = pytest.mark.render
render = pytest.importorskip("lipgen.rig.render")


@pytest.fixture(scope="module")
def face():
    return FaceModel(lip_mesh(1))


def _frames(mesh, n, seed=0):
    """Lip vertices and head poses: a crude jaw drop and corner pull, small head motion."""
    rng = np.random.default_rng(seed)
    V0 = mesh.vertices
    out = []
    for k in range(n):
        V = V0.copy()
        V[:, 1] -= 0.25 * k * np.clip(-V0[:, 1], 0, 25)
        V[:, 0] *= 1 + 0.04 * k
        P = np.eye(4)
        P[:3, :3] = Rotation.from_rotvec(rng.normal(size=3) * 0.04).as_matrix()
        P[:3, 3] = rng.normal(size=3) * 3
        out.append((V, P))
    return out


def _dot_centroids(img, bg, labels, n_dots):
    """(n_dots, 2) coverage-weighted centroids (NaN where a dot is not drawn)."""
    g = img.astype(float).mean(axis=2)
    b = bg.astype(float).mean(axis=2)
    out = np.full((n_dots, 2), np.nan)
    for k in range(n_dots):
        mine = labels == 10 + k
        if mine.sum() < 2:
            continue
        from scipy import ndimage

        region = ndimage.binary_dilation(mine, iterations=1) & ((labels == 10 + k) | (labels < 10))
        ink = g[mine].min()
        w = np.clip((b - g) / np.maximum(b - ink, 1.0), 0, 1) * region
        yy, xx = np.nonzero(w)
        out[k] = np.sum(xx * w[yy, xx]) / w.sum(), np.sum(yy * w[yy, xx]) / w.sum()
    return out


def _area(uv):
    """Area (px^2) of a projected dot from its rim (shoelace)."""
    x, y = uv[:, 0], uv[:, 1]
    return 0.5 * abs(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _fully_seen(cam, X, N, inside, tris, rims, margin: int = 1) -> np.ndarray:
    """(n,) bool: dots in view of ``cam`` whose centre faces it and is unoccluded, and whose whole
    rim is in view, unoccluded and at least 6 px² in the image (the dots whose centroid is fair)."""
    whole = np.array([cam.in_view(rim, margin=margin).all() and not occluded(cam, rim, tris).any()
                      and _area(cam.project(rim)) >= 6.0 for rim in rims])
    facing = np.sum((cam.center - X) * N, axis=1) > 0
    return inside & ~occluded(cam, X, tris) & facing & whole


def _centroid_errors(rig, face, frames):
    errors = []
    with render.RigRenderer(rig) as r:
        for V, P in frames:
            scene = face.scene(V, P)
            bare = Scene(tuple(i for i in scene.items if i.name != "dots"), scene.lights, scene.ambient,
                         scene.background)
            views = r.render_views(scene, labels=True)
            bg = r.render_views(bare)
            X, N = face.marks(V, P)
            uv, _, inside = rig.project(X)
            tris = face.occluders(face.surfaces(V, P))
            rims = face.dot_rims(face.surfaces(V, P))
            for k, cam in enumerate(rig.views):
                seen = _fully_seen(cam, X, N, inside[k], tris, rims)
                c = _dot_centroids(views[k][0], bg[k][0], views[k][2], len(X))
                assert np.isfinite(c[seen]).all(), "a fully visible dot was not drawn"
                errors.append(c[seen] - uv[k][seen])
    return np.vstack(errors)


def test_rendered_dots_land_on_truth_projections(face):
    err = _centroid_errors(default_rig(), face, _frames(face.mesh, 2))
    rms = np.sqrt(np.mean(np.sum(err**2, axis=1)))
    assert len(err) >= 40
    assert rms < 0.5, f"dot centroids {rms:.3f} px RMS from the truth"
    print(f"dot centroid error {rms:.3f} px RMS over {len(err)} dots, mean {err.mean(axis=0)}")
    # a half-pixel convention slip would show as a common offset
    assert np.abs(err.mean(axis=0)).max() < 0.15, err.mean(axis=0)


def test_distorted_camera_renders_consistently(face):
    base = default_rig()
    cam = base.camera
    rig = MirrorRig(PinholeCamera(cam.K, cam.R, cam.t, cam.width, cam.height, (-0.15, 0.05)),
                    base.mirror_normal, base.mirror_offset)
    err = _centroid_errors(rig, face, _frames(face.mesh, 1, seed=3))
    assert len(err) >= 15
    assert np.sqrt(np.mean(np.sum(err**2, axis=1))) < 0.5


def test_raw_frame_depth_and_labels(face):
    rig = default_rig(320, 240)
    V, P = _frames(face.mesh, 1, seed=1)[0]
    with render.RigRenderer(rig, mirror_reflectance=0.8) as r:
        scene = face.scene(V, P)
        frame = r.render(scene, depth=True, labels=True)
        views = r.render_views(scene)
    assert frame.image.shape == (240, 320, 3) and frame.image.dtype == np.uint8
    virt, real = rig.split_views(frame.image)
    np.testing.assert_array_equal(real, views[1][0])
    np.testing.assert_array_equal(virt, np.round(views[0][0] * np.float32(0.8)).astype(np.uint8))
    # the nose's depth in each view lies within the depths drawn around its pixel
    X, _ = face.marks(V, P)
    uv, z, _ = rig.project(X[-1:])
    for k, img in enumerate(rig.split_views(frame.depth)):
        u, v = np.round(uv[k, 0]).astype(int)
        near = img[v - 1:v + 2, u - 1:u + 2]
        assert near.min() - 0.05 <= z[k, 0] <= near.max() + 0.05, (near, z[k, 0])
    for k, lab in enumerate(rig.split_views(frame.labels)):
        u, v = np.round(uv[k, 0]).astype(int)
        assert lab[v, u] == 10 + len(face.mesh.markers), "the nose dot is labelled as the nose dot"
        assert (lab == 0).any() and (lab == 1).any() and (lab == 2).any()


def test_pyrender_is_imported_only_when_rendering():
    code = ("import lipgen, lipgen.rig.render, lipgen.subject.face, lipgen.rig.camera, sys; "
            "print('pyrender' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_missing_opengl_gives_a_clear_error():
    code = ("from lipgen.rig.render import RigRenderer\nfrom lipgen.rig.camera import default_rig\n"
            "try:\n    RigRenderer(default_rig(64, 48))\nexcept Exception as e:\n"
            "    print(type(e).__name__, e)\n")
    env = {**os.environ, "PYOPENGL_PLATFORM": "osmesa", "LD_LIBRARY_PATH": "/nonexistent"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    if "osmesa" not in out.stdout.lower() and out.stdout.strip() == "":
        pytest.skip("OSMesa is installed here; cannot simulate a missing GL")
    assert out.stdout.startswith("RenderBackendError"), out.stdout + out.stderr
    assert "apt install" in out.stdout


def test_calibration_board_corners_match_truth():
    """The chessboard frames agree with their true poses: corners found by OpenCV vs projections."""
    from lipgen.recon.calibrate import find_corners
    from lipgen.rig.target import Chessboard, board_poses, board_scene

    rig = default_rig()
    board = Chessboard(9, 6, 8.0)
    poses = board_poses(rig, board, 2, seed=7)
    with render.RigRenderer(rig) as r:
        for P in poses:
            uv = rig.project(board.object_points() @ P[:3, :3].T + P[:3, 3])[0]
            for v, img in enumerate(rig.split_views(r.render(board_scene(board, P)).image)):
                found = find_corners(img, board)
                assert found is not None
                err = np.linalg.norm(found - uv[v], axis=1)
                assert np.median(err) < 0.2 and np.percentile(err, 90) < 0.4, err
