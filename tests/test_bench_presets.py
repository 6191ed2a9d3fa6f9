"""The presets bench's helpers: the four-way triangle split keeps the surface it splits; the hard
preset's sampling against dense references."""

import contextlib

import numpy as np
import pytest

from lipgen.bench.preset_frames import _split4
from lipgen.rig.scene import Material, MeshItem, vertex_normals


def _areas(V, F):
    return 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)


def test_split4_same_surface_four_times_the_triangles():
    rng = np.random.default_rng(3)
    V = rng.normal(size=(12, 3))
    F = np.array([[0, 1, 2], [0, 2, 3], [3, 2, 4], [5, 6, 7], [8, 9, 10], [9, 11, 10]])
    mats = (Material("a", (0.5, 0.5, 0.5)), Material("b", (0.2, 0.3, 0.4)))
    fm = np.array([0, 1, 0, 1, 0, 1])
    item = MeshItem("face", V, F, mats, fm, vertex_normals(V, F), rng.random((12, 2)))
    s = _split4(item)
    assert s.faces.shape == (4 * len(F), 3)
    # shared edges get one midpoint: 6 triangles here have 15 distinct edges
    assert len(s.vertices) == 12 + 15
    np.testing.assert_array_equal(s.vertices[:12], V)
    # each child lies in its parent's plane and the children tile the parent exactly
    parent = np.tile(np.arange(len(F)), 4)
    np.testing.assert_allclose(np.bincount(parent, _areas(s.vertices, s.faces)), _areas(V, F), rtol=1e-12)
    for k, tri in enumerate(s.faces):
        a, b, c = V[F[parent[k]]]
        n = np.cross(b - a, c - a)
        np.testing.assert_allclose((s.vertices[tri] - a) @ n, 0.0, atol=1e-12)
    np.testing.assert_array_equal(s.face_material, np.tile(item.face_material, 4))
    # the midpoint of edge (0, 1) carries the mean of its ends' uv and normals
    m = np.flatnonzero(np.all(np.isclose(s.vertices, 0.5 * (V[0] + V[1])), axis=1))
    assert len(m) == 1
    np.testing.assert_allclose(s.uv[m[0]], 0.5 * (item.uv[0] + item.uv[1]))
    np.testing.assert_allclose(s.normals[m[0]], 0.5 * (item.normals[0] + item.normals[1]))


@pytest.mark.slow(cover="tests/test_imaging.py::test_motion_blur_instants_and_lighting_are_seeded")
@pytest.mark.render
def test_hard_sampling_stays_below_the_sensor_noise(tmp_path):
    """The hard preset's blur instants (at most ``blur_step_px`` apart) and head mesh against dense
    references: on the face's pixels the difference stays under a third (blur) and a half (head) of
    the sensor's shot and read noise, and the ink dots' centroids move by under 0.1 px RMS."""
    pytest.importorskip("pyrender")
    from lipgen._threads import limit_worker_threads
    from lipgen.bench.preset_fidelity import measure
    from lipgen.bench.preset_frames import _contexts

    limit_worker_threads(1)
    workers, motion = _contexts(tmp_path, 3)
    try:
        f = measure(workers["hard"], motion, [1, 2])
    finally:
        for w in workers.values():
            with contextlib.suppress(Exception):
                w["renderer"].close()
    sigma = f["sensor_noise"]["shot_read"]
    assert 1.0 < sigma < f["sensor_noise"]["with_bayer_jpeg"]
    assert f["blur"]["preset"]["face_rms"] < sigma / 3 and f["head"]["preset"]["face_rms"] < sigma / 2
    for part in (f["blur"]["preset"], f["head"]["preset"]):
        assert part["dot_shift_rms_px"] < 0.1
