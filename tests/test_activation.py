"""Activation curves, viseme scripts and head motion of the synthetic subject."""

import numpy as np
import pytest

from lipgen.subject.activation import (
    ACTIONS,
    CLASSIC_ACTIONS,
    ONE_SIDED,
    VISEMES,
    head_motion,
    parse_script,
    random_activations,
    viseme_activations,
)


def test_random_activations_are_seeded_smooth_and_bounded():
    a = random_activations(150, seed=4)
    assert a.shape == (150, len(ACTIONS))
    assert a.tobytes() == random_activations(150, seed=4).tobytes()
    assert not np.array_equal(a, random_activations(150, seed=5))
    assert a.min() >= 0 and a.max() < 1
    symmetric = [i for i, n in enumerate(CLASSIC_ACTIONS) if n not in ONE_SIDED]
    assert (a[:, symmetric].max(axis=0) > 0.05).all()  # every symmetric action is used
    assert (a.max(axis=0) > 0.05).sum() > len(symmetric)  # and some one-sided ones
    assert not a[:, len(CLASSIC_ACTIONS):].any()  # the independent sources are not drawn here
    assert np.abs(np.diff(a, axis=0)).max() < 0.35  # no jumps between frames at 30 fps


def test_viseme_script_parsing_and_timing():
    seq = parse_script("aa:0.3, EE:0.2 oo  M:0.15 F b sil:0.1")
    assert seq == [("AA", 0.3), ("EE", 0.2), ("OO", 0.2), ("M", 0.15), ("F", 0.2), ("M", 0.2),
                   ("REST", 0.1)]
    act = viseme_activations("REST:0.5 AA:0.6 REST:0.5", fps=30)
    assert act.shape == (48, len(ACTIONS))
    jaw = act[:, ACTIONS.index("jaw_open")]
    assert jaw[:5].max() == 0 and jaw[-5:].max() == 0  # starts and ends at rest
    assert np.isclose(jaw.max(), VISEMES["AA"]["jaw_open"])  # a long viseme reaches its target
    assert 14 <= int(np.argmax(jaw)) <= 33
    assert np.abs(np.diff(jaw)).max() < 0.3  # coarticulation smooths the steps
    assert viseme_activations("AA", fps=60).shape[0] == 12


@pytest.mark.parametrize("script, message", [
    ("AA XX:0.2", r"unknown viseme 'XX'.*REST, AA"),
    ("AA:fast", r"cannot read viseme token 'AA:fast'"),
    ("AA:0", r"more than 0 s"),
    ("   ", r"empty"),
])
def test_viseme_script_errors(script, message):
    with pytest.raises(ValueError, match=message):
        viseme_activations(script)


def test_head_motion_is_rigid_small_and_seeded():
    P = head_motion(90, seed=2, max_rotation_deg=3.0, max_translation_mm=2.0)
    assert P.shape == (90, 4, 4) and P.tobytes() == head_motion(90, seed=2, max_rotation_deg=3.0,
                                                                  max_translation_mm=2.0).tobytes()
    R = P[:, :3, :3]
    assert np.allclose(R @ R.transpose(0, 2, 1), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1.0)
    assert np.allclose(P[:, 3], [0, 0, 0, 1])
    angle = np.degrees(np.arccos(np.clip((np.trace(R, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    assert angle.max() < 3.0 * np.sqrt(3) + 1e-9
    pivot = np.array([0.0, -70.0, -90.0])
    moved = np.einsum("fij,j->fi", R, pivot) + P[:, :3, 3]  # where the pivot goes
    assert np.linalg.norm(moved - pivot, axis=1).max() <= 2.0 * np.sqrt(3) + 1e-9
