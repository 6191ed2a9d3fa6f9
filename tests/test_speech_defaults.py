"""The shipped default lips of lip sync against the code that builds them, and the subject's
motion on a model's nodes (NodeMotion) against the subject itself."""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from lipgen.speech.defaults import NodeMotion, build_default_lips, load_default_lips, node_motion
from lipgen.subject.activation import ACTIONS, action_index, random_activations

REGENERATE = ('write them again: python -c "from lipgen.speech.defaults import save_default_lips; '
              'save_default_lips()"')


@pytest.fixture(scope="module")
def fresh():
    return build_default_lips()


def test_shipped_default_lips_are_what_the_code_builds(fresh):
    model, mesh, motion = fresh
    s_model, s_mesh, s_motion = load_default_lips()
    assert s_mesh.topology_id == mesh.topology_id, REGENERATE
    # to rounding: other numpy/scipy builds differ in the last bit (7e-15 mm on 2026-12-07's rebuilt venv)
    assert np.allclose(s_mesh.vertices, mesh.vertices, rtol=0, atol=1e-12), REGENERATE
    for name in ("faces", "regions", "anchors", "markers", "nose"):
        assert np.array_equal(getattr(s_mesh, name), getattr(mesh, name)), (name, REGENERATE)
    assert s_model.topology_id_ == model.topology_id_ and s_model.n_frames_ == model.n_frames_
    assert np.allclose(s_model.mean_, model.mean_, rtol=0, atol=1e-9), REGENERATE
    assert np.allclose(s_model.components_, model.components_, rtol=0, atol=1e-7), REGENERATE
    assert np.allclose(s_model.explained_variance_, model.explained_variance_, rtol=1e-7), REGENERATE
    for name in ("vertices", "responses", "jaw_basis", "contact_response"):
        same = np.allclose(getattr(s_motion, name), getattr(motion, name), rtol=0, atol=1e-9)
        assert same, (name, REGENERATE)
    assert np.array_equal(s_motion.contact_pairs, motion.contact_pairs) and s_motion.n_out == motion.n_out
    assert s_motion.jaw_max_angle == pytest.approx(motion.jaw_max_angle, rel=1e-12)


def test_node_motion_is_the_subjects_motion_on_those_nodes():
    from lipgen.speech.lipsync import performer

    subject = performer(1, 0)
    n = 201
    motion = node_motion(subject, n)
    rng = np.random.default_rng(3)
    A = np.concatenate([random_activations(90, seed=2, fps=30.0),
                        rng.uniform(0.0, 1.0, (40, len(ACTIONS))),  # jaw shifts, lips pressed together
                        np.eye(len(ACTIONS)), np.zeros((1, len(ACTIONS)))])
    A[:20, action_index("jaw_open")] = np.linspace(0.0, 2.0, 20)  # the whole range of the jaw
    want = subject.displacements(A)[:, :n]
    got = motion.displacements(A)
    assert got.shape == want.shape
    assert np.abs(got - want).max() < 1e-9 * np.abs(want).max()
    with pytest.raises(ValueError, match=r"shape \(F, "):
        motion.displacements(A[:, :3])


def test_node_motion_file_round_trip(tmp_path, fresh):
    motion = fresh[2]
    motion.save(tmp_path / "m.npz")
    back = NodeMotion.load(tmp_path / "m.npz")
    A = random_activations(30, seed=1, fps=30.0)
    assert np.array_equal(back.displacements(A), motion.displacements(A))


def test_lipsync_projection_uses_the_default_lips():
    from lipgen.mesh.procedural import lip_mesh
    ls = importlib.import_module("lipgen.speech.lipsync")  # the package exports a function of that name

    model = ls.default_model()
    assert ls.model_resolution(model) == 0 and ls.model_mesh(0).topology_id == lip_mesh(0).topology_id
    A = random_activations(60, seed=4, fps=30.0)
    want = model.project(ls.performer(0, 0).displacements(A)[:, :model.n_nodes_])
    assert np.allclose(ls.project_activations(A, model, 0), want, rtol=0, atol=1e-9)


def test_missing_default_lips_files_are_built(monkeypatch, tmp_path, fresh):
    from lipgen.speech import defaults

    monkeypatch.setattr(defaults, "DATA_DIR", tmp_path)  # an install without the data files
    defaults.load_default_lips.cache_clear()
    try:
        model, mesh, motion = defaults.load_default_lips()
    finally:
        defaults.load_default_lips.cache_clear()
    assert np.allclose(model.components_, fresh[0].components_, rtol=0, atol=1e-12)
    assert mesh.topology_id == fresh[1].topology_id and motion.n_out == fresh[2].n_out
