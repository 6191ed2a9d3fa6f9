"""Ink dots at surface points of the truth subject, 1-2 mm from the model's markers."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from lipgen.mesh.procedural import lip_mesh
from lipgen.subject.decal import place_decal
from lipgen.subject.face import FaceModel
from lipgen.subject.inkdots import (
    DOT_SEPARATION_MM,
    SurfaceDots,
    closest_points,
    dot_positions,
    place_dots,
    similarity_fit,
)
from lipgen.subject.motion import default_subject, random_activations, simulate
from lipgen.subject.shape import sample_shape, shaped_mesh


def test_closest_points_agree_with_dense_sampling():
    rng = np.random.default_rng(0)
    tri = rng.normal(size=(5, 3, 3)) * 3
    pts = rng.normal(size=(40, 3)) * 4
    f, b, q = closest_points(pts, tri)
    assert np.allclose(np.einsum("pj,pjd->pd", b, tri[f]), q)
    assert (b >= -1e-12).all() and np.allclose(b.sum(axis=1), 1)
    # independent: a fine barycentric grid over every triangle
    u, v = np.meshgrid(np.linspace(0, 1, 301), np.linspace(0, 1, 301))
    keep = u + v <= 1
    B = np.stack([1 - u[keep] - v[keep], u[keep], v[keep]], 1)
    S = np.einsum("sj,tjd->tsd", B, tri).reshape(-1, 3)
    brute = cKDTree(S).query(pts)[0]  # the nearest of the 226,000 samples, exactly
    got = np.linalg.norm(q - pts, axis=1)
    assert (got <= brute + 1e-9).all() and np.allclose(got, brute, atol=0.05)


def test_similarity_fit_recovers_a_transform():
    rng = np.random.default_rng(1)
    X = rng.normal(size=(30, 3))
    A = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    R = A * np.sign(np.linalg.det(A))
    s, R2, t = similarity_fit(X, 1.3 * X @ R.T + [1, 2, 3])
    assert s == pytest.approx(1.3) and np.allclose(R2, R) and np.allclose(t, [1, 2, 3])


@pytest.mark.parametrize("subject_seed", [0, 1, 2, 3, 4, 5])
def test_dots_are_1_to_2_mm_from_the_registered_model_markers(subject_seed):
    model, fine = lip_mesh(0), lip_mesh(1)
    truth = shaped_mesh(fine, sample_shape(subject_seed))
    dots = place_dots(truth, model, subject_seed)
    P = dot_positions(dots, truth.faces, truth.vertices)
    s, R, t = similarity_fit(model.vertices, truth.vertices[: model.n_nodes])
    goal = s * model.vertices[model.markers] @ R.T + t
    dist = np.linalg.norm(P - goal, axis=1)
    assert dist.min() >= 1.0 - 1e-9 and dist.min() >= 0.5  # the floor, with margin
    assert np.median(dist) < 3.0
    # on the outer surface (vermilion or skin), never on the ridge rolling into the mouth
    names = np.array(truth.region_names)[truth.regions[dots.face]]
    assert set(names) <= {"lip", "skin"}
    # not at nodes: every dot is strictly inside its triangle or on an edge, off the vertices
    assert (dots.bary.max(axis=1) < 1 - 1e-6).all()


def test_the_subject_seed_draws_shape_and_dots_and_the_truth_follows_the_dots():
    a = default_subject(0, subject_seed=3)
    b = default_subject(0, subject_seed=3)
    c = default_subject(0, subject_seed=4)
    assert np.array_equal(a.dots.face, b.dots.face) and np.array_equal(a.dots.bary, b.dots.bary)
    assert not np.allclose(a.mesh.vertices, c.mesh.vertices)
    model = lip_mesh(0)
    assert np.linalg.norm(a.mesh.vertices[model.markers] - model.vertices[model.markers], axis=1).max() > 0.5
    m = simulate(a, random_activations(5, seed=2))
    idx = a.mesh.faces[a.dots.face]
    want = np.einsum("kj,fkjd->fkd", a.dots.bary, m.vertices[:, idx])
    assert np.allclose(m.markers, want)
    assert np.allclose(m.rest_markers, np.einsum("kj,kjd->kd", a.dots.bary, a.mesh.vertices[idx]))
    assert np.abs(m.markers - m.vertices[:, a.mesh.markers]).max() > 0.5  # not the nodes
    # the rendered dot's centre is the truth point
    face = FaceModel(a.mesh, dots=a.dots)
    X, N = face.marks(m.vertices[2])
    assert np.allclose(X[:16], m.markers[2]) and np.allclose(np.linalg.norm(N, axis=1), 1)
    surf = face.surfaces(m.vertices[2])
    Vf, F, Nf = surf["face"]
    centres = np.array([place_decal(d, Vf, F, Nf, 0.0)[0] for d in face.marker_decals])
    assert np.allclose(centres, m.markers[2], atol=1e-9)


def test_bad_dots_are_refused():
    with pytest.raises(ValueError, match="bary"):
        SurfaceDots.from_dict({"face": [0, 1], "bary": [[1, 0, 0]]})
    with pytest.raises(ValueError, match="sum to 1"):
        SurfaceDots.from_dict({"face": [0], "bary": [[0.5, 0.6, 0]]})
    with pytest.raises(ValueError, match="index the mesh"):
        SurfaceDots.from_dict({"face": [99], "bary": [[1, 0, 0]]}, n_faces=10)
    with pytest.raises(ValueError, match="offset_mm"):
        place_dots(lip_mesh(1), lip_mesh(0), 0, offset_mm=(2, 1))


def test_no_two_dots_overlap():
    # subject 0 (the default preset's) drew upper_mid and bow_dip 0.92 mm apart: one ink blob
    model, fine = lip_mesh(0), lip_mesh(1)
    for subject_seed in (0, 3):
        truth = shaped_mesh(fine, sample_shape(subject_seed))
        rng = [subject_seed, 0xD075]                 # as lipgen.subject.motion.default_subject draws them
        free = dot_positions(place_dots(truth, model, rng, separation_mm=0.0), truth.faces, truth.vertices)
        P = dot_positions(place_dots(truth, model, rng), truth.faces, truth.vertices)
        d_free = np.linalg.norm(free[:, None] - free[None], axis=2)[np.triu_indices(len(P), 1)]
        d = np.linalg.norm(P[:, None] - P[None], axis=2)[np.triu_indices(len(P), 1)]
        assert d_free.min() < 1.0                    # without the rule these subjects overlap
        assert d.min() >= DOT_SEPARATION_MM - 1e-9
    with pytest.raises(ValueError, match="separation_mm"):
        place_dots(lip_mesh(1), lip_mesh(0), 0, separation_mm=-1.0)
