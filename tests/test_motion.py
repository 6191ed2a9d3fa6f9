"""The synthetic subject: determinism, symmetry, magnitudes, contact, frames and bad input."""

import hashlib

import numpy as np
import pytest

from lipgen import lip_mesh
from lipgen.mesh.procedural import mirror_permutation
from lipgen.subject.motion import (
    ACTION_TARGETS_MM,
    ACTIONS,
    default_subject,
    head_motion,
    random_activations,
    simulate,
    viseme_activations,
)


@pytest.fixture(scope="module")
def subject():
    return default_subject(0)


def _one(name, value=1.0):
    a = np.zeros((1, len(ACTIONS)))
    a[0, ACTIONS.index(name)] = value
    return a


def test_truth_is_finer_and_nested_on_the_model_mesh(subject):
    coarse = lip_mesh(0)
    assert subject.mesh.n_nodes > 3 * coarse.n_nodes
    assert np.array_equal(subject.mesh.vertices[:coarse.n_nodes], coarse.vertices)
    assert np.allclose(subject.mesh.vertices[subject.mesh.markers], coarse.vertices[coarse.markers])
    assert subject.physics.mesh.n_nodes == subject.mesh.n_nodes
    # The model holds its skin border still; the truth's lower border rides on the jaw.
    chin = int(np.argmin(coarse.vertices[:, 1]))
    assert chin in coarse.anchors and chin in subject.physics.mesh.anchors
    assert simulate(subject, _one("jaw_open")).displacements[0, chin, 1] < -8.0


def test_same_seed_same_bytes():
    a = simulate(default_subject(3), random_activations(20, seed=3), head_motion(20, seed=3))
    b = simulate(default_subject(3), random_activations(20, seed=3), head_motion(20, seed=3))
    assert a.vertices.tobytes() == b.vertices.tobytes() and a.poses.tobytes() == b.poses.tobytes()
    c = simulate(default_subject(4), random_activations(20, seed=3))
    assert not np.allclose(c.vertices, a.vertices)


def test_the_truth_does_not_depend_on_the_blas_thread_count(subject):
    """Lips in contact (the LCP's small solves): OpenBLAS's SkylakeX kernels on two threads once
    rounded them differently from one thread, so a dataset's truth depended on the machine."""
    from lipgen._threads import blas_threads

    acts = viseme_activations("AA:0.2 OO:0.2 M F B P")
    with blas_threads(1, always=True):
        one = simulate(subject, acts).vertices
    with blas_threads(2, always=True):
        two = simulate(subject, acts).vertices
    up, lo = subject.contact_pairs.T
    assert (one[:, up, 1] - one[:, lo, 1]).min() < 1e-6  # the lips do touch: the LCP runs
    assert one.tobytes() == two.tobytes()


@pytest.mark.parametrize("action", ["lip_corner_puller", "jaw_open", "pucker", "lip_press"])
def test_symmetric_actions_give_mirror_symmetric_lips(subject, action):
    V = simulate(subject, _one(action)).vertices[0]
    perm = mirror_permutation(subject.mesh)
    assert np.allclose(V[perm], V * [-1.0, 1.0, 1.0], atol=1e-8)
    assert np.abs(V - subject.mesh.vertices).max() > 1.0  # it does move


@pytest.mark.parametrize("action", ["upper_lip_raiser", "lip_corner_puller", "lip_corner_depressor",
                                    "jaw_shift"])
def test_one_sided_actions_mirror_each_other(subject, action):
    """The left variant is the mirror image of the right one, and it is not symmetric itself."""
    perm = mirror_permutation(subject.mesh)
    left = simulate(subject, _one(f"{action}_left")).vertices[0]
    right = simulate(subject, _one(f"{action}_right")).vertices[0]
    assert np.allclose(left[perm] * [-1.0, 1.0, 1.0], right, atol=1e-8)
    U = left - subject.mesh.vertices
    assert np.abs(U[perm] * [-1.0, 1.0, 1.0] - U).max() > 1.0  # one-sided: far from symmetric
    mesh = subject.mesh
    if action == "jaw_shift":  # the lower lip rides the jaw to the subject's left, the upper barely
        lower, upper = U[mesh.marker_index("lower_mid")], U[mesh.marker_index("upper_mid")]
        assert 1.5 < lower[0] < 3.0 and abs(upper[0]) < 0.5 * lower[0]
    else:  # the calibrated side moves by its target; the other side much less
        marker, mm = ACTION_TARGETS_MM[f"{action}_left"]
        other = marker.replace("left", "right")
        assert 0.75 * mm < np.linalg.norm(U[mesh.marker_index(marker)]) < 1.25 * mm
        assert np.linalg.norm(U[mesh.marker_index(other)]) < 0.3 * mm


def test_random_activations_mix_one_sided_gestures():
    a = random_activations(300, seed=2)
    sided = [ACTIONS.index(n) for n in ACTIONS[:16] if n.endswith(("_left", "_right"))]
    assert len(sided) == 8 and (a[:, sided].max(axis=0) > 0.05).all()
    # Appending actions kept the older columns' seeded draws (hash of the 8-action version's output).
    assert hashlib.sha256(np.ascontiguousarray(a[:, :8]).tobytes()).hexdigest()[:16] == "3b6fbc51f4f4ab2e"
    assert ACTIONS[:8] == ("jaw_open", "upper_lip_raiser", "lip_corner_puller", "lip_corner_depressor",
                           "pucker", "lip_press", "funneler", "lower_lip_protrusion")


def test_calibrated_magnitudes_in_mm(subject):
    mesh = subject.mesh
    for action, (marker, mm) in ACTION_TARGETS_MM.items():
        a, k = ACTIONS.index(action), mesh.marker_index(marker)
        if action != "jaw_open":  # the elastic response is scaled to the target exactly
            assert np.isclose(np.linalg.norm(subject.responses[a, k]), mm)
        if action.startswith("lip_press"):
            continue  # the lips meet first: contact stops the press short of its free response
        U = simulate(subject, _one(action)).displacements[0, k]
        # Contact and the arch wrap act after calibration, so allow a little slack.
        assert 0.75 * mm < np.linalg.norm(U) < 1.25 * mm, (action, U)
    jaw = simulate(subject, _one("jaw_open")).displacements[0]
    assert jaw[mesh.marker_index("lower_mid"), 1] < -10  # the lower lip drops 10-20 mm
    assert abs(jaw[mesh.marker_index("upper_mid"), 1]) < 2
    smile = simulate(subject, _one("lip_corner_puller")).displacements[0, mesh.marker_index("corner_left")]
    assert smile[0] > 4 and smile[1] > 1 and smile[2] < 0  # out, up and back round the face


def test_motion_is_nonlinear_in_the_jaw(subject):
    half = simulate(subject, _one("jaw_open", 0.5)).displacements[0]
    full = simulate(subject, _one("jaw_open", 1.0)).displacements[0]
    lower = subject.mesh.marker_index("lower_mid")
    assert np.linalg.norm(full[lower] - 2 * half[lower]) > 0.3  # mm: arcs, not lines


def test_lips_touch_but_do_not_cross(subject):
    up, lo = subject.contact_pairs.T
    for act in (_one("lip_press"), _one("lip_press", 1.5) + _one("lip_corner_puller"),
                viseme_activations("M:0.4 B P")):
        V = simulate(subject, act).vertices
        gap = V[:, up, 1] - V[:, lo, 1]
        assert gap.min() > -1e-9
    assert (simulate(subject, _one("lip_press")).vertices[0, up, 1]
            - simulate(subject, _one("lip_press")).vertices[0, lo, 1]).min() < 1e-6  # they touch


def test_world_frame_follows_the_head_pose(subject):
    poses = head_motion(5, seed=1)
    m = simulate(subject, random_activations(5, seed=1), head=poses)
    R, t = poses[:, :3, :3], poses[:, :3, 3]
    assert m.markers.shape == (5, 16, 3) and m.nose_world.shape == (5, 3)
    assert np.allclose(m.markers_world, np.einsum("fij,fkj->fki", R, m.markers) + t[:, None])
    assert np.allclose(m.nose_world, np.einsum("fij,j->fi", R, subject.mesh.nose) + t)
    assert np.allclose(m.vertices_world[:, subject.mesh.markers], m.markers_world)
    assert np.allclose(m.times, np.arange(5) / 30.0)


def test_bad_inputs(subject):
    with pytest.raises(ValueError, match=r"unknown action 'smirk'.*jaw_open"):
        simulate(subject, {"smirk": np.zeros(3)})
    with pytest.raises(ValueError, match=rf"shape \(F, {len(ACTIONS)}\)"):
        simulate(subject, np.zeros((4, 5)))
    with pytest.raises(ValueError, match=r"\[0, 2\]"):
        simulate(subject, -_one("pucker"))
    bad = np.tile(np.eye(4), (1, 1, 1))
    bad[0, 0, 0] = 2.0
    with pytest.raises(ValueError, match="rigid"):
        simulate(subject, _one("pucker"), head=bad)
    with pytest.raises(ValueError, match="finer mesh"):
        default_subject(0, resolution=0)
    m = simulate(subject, {"pucker": np.linspace(0, 1, 4), "jaw_open": np.full(4, 0.2)})
    assert m.activations.shape == (4, len(ACTIONS)) and m.activations[3, ACTIONS.index("pucker")] == 1
