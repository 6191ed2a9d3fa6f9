"""The visibility ray cast (lipgen.rig.visibility) against an all-pairs cast with no culling."""

import numpy as np
import pytest

from lipgen.rig import visibility
from lipgen.rig.pinhole import PinholeCamera


def _all_pairs(cam, pts, tris):
    n, m = len(pts), len(tris)
    o = np.broadcast_to(cam.center, (n * m, 3))
    hit = visibility.segment_hits(o, np.repeat(pts, m, 0), np.tile(tris, (n, 1, 1)))
    return hit.reshape(n, m).any(axis=1)


@pytest.mark.parametrize("dist", [None, (-0.3, 0.1, 0.002, -0.001, 0.0)])
@pytest.mark.parametrize("block", [None, 7])
def test_culled_cast_equals_all_pairs_with_triangles_behind_the_camera(monkeypatch, block, dist):
    """Also through a strongly distorting lens (the culling boxes are taken in its pinhole image)."""
    if block is not None:  # several candidate blocks (7 point-box tests per block: one point at a time)
        monkeypatch.setattr(visibility, "_PAIR_BLOCK", block)
    rng = np.random.default_rng(4)
    cam = PinholeCamera.look_at([0, 0, 300.0], [0, 0, 0], 160, 120, 200.0)
    if dist is not None:
        cam = PinholeCamera(cam.K, cam.R, cam.t, cam.width, cam.height, dist)
    centers = rng.uniform([-40, -30, -20], [40, 30, 20], size=(300, 3))
    tris = centers[:, None, :] + rng.normal(size=(300, 3, 3)) * 4
    # big triangles with a vertex behind the camera, and one passing beside it
    big = np.array([[[-30.0, -30, 0], [30, -30, 0], [0, 10, 400]], [[-5.0, 5, 0], [5, 5, 0], [0, 400, 350]]])
    tris = np.concatenate([tris, big])
    pts = rng.uniform([-40, -30, -25], [40, 30, 25], size=(250, 3))
    got = visibility.occluded(cam, pts, tris)
    want = _all_pairs(cam, pts, tris)
    inside = cam.in_view(pts)
    np.testing.assert_array_equal(got[inside], want[inside])
    assert not got[~inside].any()  # outside the image: not occluded (in_view is the caller's test)
    assert want[inside].any() and not want[inside].all()


def test_no_points_or_no_triangles():
    cam = PinholeCamera.look_at([0, 0, 300.0], [0, 0, 0], 160, 120, 200.0)
    assert visibility.occluded(cam, np.zeros((0, 3)), np.zeros((3, 3, 3))).shape == (0,)
    assert not visibility.occluded(cam, np.zeros((2, 3)), np.zeros((0, 3, 3))).any()


@pytest.mark.parametrize("block", [None, 1, 50])
def test_box_pairs_are_every_point_in_every_box(monkeypatch, block):
    """The sorted search finds exactly the pairs of an all-pairs test: ties in x, points on box
    edges, infinite boxes, empty boxes, and blocks of any size."""
    if block is not None:
        monkeypatch.setattr(visibility, "_PAIR_BLOCK", block)
    rng = np.random.default_rng(7)
    q = rng.integers(0, 20, size=(60, 2)).astype(float)  # many ties; some points on box edges
    a, b = rng.integers(0, 20, size=(2, 2, 80)).astype(float)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    lo[:, :3], hi[:, :3] = -np.inf, np.inf  # boxes over everything (a vertex behind the camera)
    lo[0, 3], hi[0, 3] = 5.0, 4.0  # an empty box
    i, j = visibility._box_pairs(q, lo, hi)
    inside = ((q[:, :1] >= lo[0]) & (q[:, :1] <= hi[0]) & (q[:, 1:] >= lo[1]) & (q[:, 1:] <= hi[1]))
    want = set(zip(*np.nonzero(inside), strict=True))
    assert len(i) == len(want) == len(set(zip(i, j, strict=True)))
    assert set(zip(i.tolist(), j.tolist(), strict=True)) == want
