"""The truth subject's shape space: sampled per subject seed, measured back, kept in range."""

import numpy as np
import pytest

from lipgen.mesh.procedural import lip_mesh
from lipgen.subject.shape import (
    SHAPE_RANGES,
    ShapeParams,
    measure_shape,
    model_shape,
    sample_shape,
    shaped_mesh,
)


@pytest.fixture(scope="module")
def fine():
    return lip_mesh(1)


def test_sampling_is_seeded_in_range_and_varies():
    a, b = sample_shape(7), sample_shape(7)
    assert a == b
    draws = [sample_shape(s).to_dict() for s in range(40)]
    for name, (lo, hi) in SHAPE_RANGES.items():
        vals = np.array([d[name] for d in draws])
        assert ((vals >= lo) & (vals <= hi)).all()
        assert vals.std() > 0.05 * (hi - lo)  # subjects really differ


@pytest.mark.parametrize("seed", [0, 3, 11])
def test_shaped_mesh_measures_its_parameters(fine, seed):
    p = sample_shape(seed)
    got = measure_shape(shaped_mesh(fine, p))
    for name, want in p.to_dict().items():
        assert got[name] == pytest.approx(want, abs=0.02), name


def test_subject_seed_changes_the_rest_shape_but_not_the_topology(fine):
    model = lip_mesh(0)
    for seed in (1, 2):
        m = shaped_mesh(fine, sample_shape(seed))
        assert np.array_equal(m.faces, fine.faces) and np.array_equal(m.markers, fine.markers)
        assert np.array_equal(m.anchors, fine.anchors) and np.array_equal(m.nose, fine.nose)
        moved = np.linalg.norm(m.vertices[: model.n_nodes] - model.vertices, axis=1)
        assert np.median(moved) > 0.5
        # no element is turned over by the warp
        def normals(V):
            t = V[fine.faces]
            n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
            return n / np.linalg.norm(n, axis=1, keepdims=True)
        assert (np.sum(normals(m.vertices) * normals(fine.vertices), axis=1) > 0.2).all()


def test_the_model_shape_is_in_range_and_the_identity_warp_is_exact(fine):
    assert isinstance(model_shape(), ShapeParams)  # in range
    V = shaped_mesh(fine, ShapeParams(**measure_shape(fine))).vertices
    assert np.abs(V - fine.vertices).max() < 0.05


def test_bad_shapes_name_the_value_and_range():
    d = model_shape().to_dict()
    with pytest.raises(ValueError, match=r"width = 80.0 mm is outside its documented range \[44.0, 62.0\]"):
        ShapeParams(**{**d, "width": 80.0})
    with pytest.raises(ValueError, match="asymmetry"):
        ShapeParams(**{**d, "asymmetry": float("nan")})
    with pytest.raises(TypeError, match="cupid_bow"):
        ShapeParams(**{**d, "cupid_bow": "big"})
    with pytest.raises(ValueError, match=r"subject seed -1 is outside \[0, 4294967295\]"):
        sample_shape(-1)
    with pytest.raises(TypeError, match="subject seed"):
        sample_shape(1.5)
    with pytest.raises(ValueError, match="unknown"):
        ShapeParams.from_dict({**d, "chin": 1.0})
    with pytest.raises(TypeError, match="ShapeParams"):
        shaped_mesh(lip_mesh(0), d)
