"""A normalisation reference given by the caller (normalize_markers(reference=...),
lipgen.recon.rereference): a recording's own reference passed back gives its own result; a second
recording of the same subject normalised with the first one's reference agrees with it on where
rest is (the per-marker constant offset), where its own reference, fitted on a frame that is not
at rest, does not."""

import numpy as np
import pytest

from lipgen.fem import Physics
from lipgen.mesh.procedural import lip_mesh
from lipgen.recon.headpose import rotation_matrix
from lipgen.recon.normalize import lip_subsets, normalize_markers
from lipgen.recon.similarity import Similarity
from lipgen.subject.motion import ACTIONS, default_subject


@pytest.fixture(scope="module")
def model():
    mesh = lip_mesh(0)
    return mesh, Physics(mesh)


@pytest.fixture(scope="module")
def recordings(model):
    """Two recordings of one subject whose rest shape is not the model's (lab frame, another scale):
    A starts at rest; B is never at rest (the jaw stays open). Returns the lab marks, the nose and
    the true model-frame marks of each."""
    mesh, _ = model
    M, nose = mesh.vertices[mesh.markers], mesh.nose
    rng = np.random.default_rng(5)
    shape = rng.normal(0, 0.8, M.shape)  # the subject's rest differs from the model's by ~1.4 mm
    subject = default_subject(0)
    jaw = ACTIONS.index("jaw_open")
    out = {}
    lab = rotation_matrix([0.2, -0.6, 0.3])
    for name, gen, base in (("A", np.random.default_rng(6), 0.0), ("B", np.random.default_rng(7), 0.5)):
        F = 12
        act = np.clip(gen.normal(0, 0.15, (F, len(ACTIONS))), 0, None)
        act[:, jaw] += base
        if base == 0.0:
            act[0] = 0.0  # A's first frame is the rest
        U = subject.displacements(act)[:, subject.mesh.markers]
        true = M + shape + U  # model frame, mm
        Qs = rotation_matrix(gen.uniform(-1, 1, (F, 3)) * np.deg2rad(3.0))
        t = gen.normal(0, 4, (F, 3))  # where the nose is: the head turns about it and moves
        X = np.einsum("fij,fpj->fpi", Qs, true - nose) + t[:, None]
        out[name] = (1.25 * X @ lab.T, 1.25 * t @ lab.T, true)
    return out


@pytest.mark.parametrize("method", ["thesis", "least-force"])
def test_own_reference_passed_back_gives_the_default(model, recordings, method):
    mesh, physics = model
    M = mesh.vertices[mesh.markers]
    up, lo = lip_subsets(mesh.marker_names)
    X, N, _ = recordings["B"]
    own = normalize_markers(X, N, up, lo, M, model_nose=mesh.nose, reference_frame="auto", method=method,
                            physics=physics)
    again = normalize_markers(X, N, up, lo, M, model_nose=mesh.nose, method=method, physics=physics,
                              reference=own.similarity)
    assert np.allclose(again.markers, own.markers, atol=1e-7)
    assert again.similarity.scale == own.similarity.scale and again.reference_frame == -1
    assert np.allclose(again.similarity.apply(np.einsum("fij,fpj->fpi", again.rotations, X - N[:, None])),
                       again.markers, atol=1e-9)


@pytest.mark.parametrize("method", ["thesis", "least-force"])
def test_another_recordings_reference_agrees_on_rest(model, recordings, method):
    mesh, physics = model
    M = mesh.vertices[mesh.markers]
    up, lo = lip_subsets(mesh.marker_names)

    def norm(name, **kw):
        X, N, _ = recordings[name]
        return normalize_markers(X, N, up, lo, M, model_nose=mesh.nose, method=method, physics=physics, **kw)

    def offset(name, res):  # each marker's mean error over the frames (model frame, mm)
        return (res.markers - recordings[name][2]).mean(axis=0)

    a = norm("A", reference_frame="auto")
    b_own = norm("B", reference_frame="auto")
    b_a = norm("B", reference=a.similarity)
    # the scale: A's (its most neutral frame is at rest) is the true 1 / 1.25 within the shape's
    # misfit; B's own, fitted on an open-jaw frame, is off by more
    assert abs(b_own.similarity.scale * 1.25 - 1) > 2 * abs(a.similarity.scale * 1.25 - 1)
    disagree_own = np.sqrt(np.mean(np.sum((offset("B", b_own) - offset("A", a)) ** 2, axis=1)))
    disagree_a = np.sqrt(np.mean(np.sum((offset("B", b_a) - offset("A", a)) ** 2, axis=1)))
    assert disagree_a < 0.5 * disagree_own  # measured: thesis 3.57 -> 0.19 mm, least-force 3.28 -> 1.38 mm
    rms = {k: np.sqrt(np.mean(np.sum(offset("B", r) ** 2, axis=1))) for k, r in (("own", b_own), ("A", b_a))}
    assert rms["A"] < rms["own"]  # measured: thesis 4.08 -> 0.72 mm, least-force 3.71 -> 2.82 mm


def test_bad_reference(model, recordings):
    mesh, physics = model
    M = mesh.vertices[mesh.markers]
    up, lo = lip_subsets(mesh.marker_names)
    X, N, _ = recordings["A"]
    with pytest.raises(TypeError, match="reference must be a Similarity"):
        normalize_markers(X, N, up, lo, M, model_nose=mesh.nose, reference=np.eye(4))
    with pytest.raises(ValueError, match="reference.scale"):
        normalize_markers(X, N, up, lo, M, model_nose=mesh.nose,
                          reference=Similarity(0.0, np.eye(3), np.zeros(3)))


def _reconstruction(X, N, mesh):
    """A Reconstruction of lab marks X (F, P, 3) and nose N (F, 3), every marker accepted."""
    from lipgen.recon.pipeline import Reconstruction

    F, P = X.shape[:2]
    return Reconstruction(fields=np.full((F, len(mesh.vertices), 3), np.nan),
                          markers=np.full((F, P, 3), np.nan), visible=np.ones((F, P), bool),
                          lab_points=np.concatenate([X, N[:, None]], axis=1), ray_gap=np.zeros((F, P + 1)),
                          uv=np.zeros((2, F, P + 1, 2)), status=np.zeros((2, F, P + 1), np.int8),
                          score=np.ones((2, F, P + 1)), frame_index=np.arange(F), lab_to_board=np.eye(4),
                          similarity=np.eye(4), rotations=np.tile(np.eye(3), (F, 1, 1)),
                          info={"normalisation": {"method": "least-force"}})


def test_renormalize_reaches_fields_from_the_rest_given(model, recordings):
    """rest=None reaches from the model's markers; rest=(P, 3) from those (NaN rows: the model's);
    metric_renormalize is scale 1 with the rest of its own frames (recording_rest)."""
    from lipgen.recon.rereference import renormalize
    from lipgen.recon.rest import metric_renormalize, recording_rest
    from lipgen.recon.steps import reach_fields

    mesh, physics = model
    M = mesh.vertices[mesh.markers]
    X, N, true = recordings["A"]
    recon = _reconstruction(X, N, mesh)
    unit = Similarity(1.0, rotation_matrix([0.2, -0.6, 0.3]).T, np.zeros(3))
    plain = renormalize(recon, unit, physics)
    assert np.array_equal(plain.info["rest"], M) and plain.info["rest_source"]["kind"] == "model"
    rest = true[0].copy()  # A's first frame is the subject's rest
    rest[3] = np.nan
    given = renormalize(recon, unit, physics, rest=rest)
    used = np.asarray(given.info["rest"])
    assert np.array_equal(used[3], M[3]) and np.array_equal(np.delete(used, 3, 0), np.delete(rest, 3, 0))
    assert np.array_equal(given.markers, plain.markers)
    expect = reach_fields(physics, given.markers - used, given.visible, mesh.markers, 4)
    assert np.allclose(given.fields, expect, equal_nan=True, atol=1e-12)
    assert not np.allclose(given.fields, plain.fields, equal_nan=True)
    assert given.info["rest_source"]["kind"] == "given"
    # the record follows the fields: measured again from the model's rest, the given rest is gone
    again = renormalize(given, unit, physics)
    assert np.array_equal(again.info["rest"], M) and again.info["rest_source"]["kind"] == "model"
    metric, quiet = metric_renormalize(recon, physics)
    assert metric.info["normalisation"]["scale"] == 1.0
    assert np.allclose(quiet, recording_rest(metric.markers, metric.visible, M), equal_nan=True)
    with pytest.raises(TypeError, match="rest must be numeric"):
        renormalize(recon, unit, physics, rest="quiet")
    with pytest.raises(ValueError, match="rest"):
        renormalize(recon, unit, physics, rest=np.zeros((3, 3)))
