"""The speech-like motion of independent sources (presets default and hard)."""

import numpy as np
import pytest

from lipgen.subject.activation import ACTIONS, VISEMES, action_index
from lipgen.subject.independent import (
    BILATERAL,
    INDEPENDENT_SOURCES,
    JAW_GAIN,
    RESIDUAL_MM,
    _at_dots,
    independent_activations,
    residual_motion,
    simulate_independent,
)


@pytest.fixture(scope="module")
def subject():
    from lipgen.subject.motion import default_subject

    return default_subject(0, 1, subject_seed=0)


def _columns(name):
    if name == "jaw_shift":
        return [action_index("jaw_shift_left"), action_index("jaw_shift_right")]
    return [action_index(name)]


def test_activations_are_seeded_bounded_and_use_every_source_one_side_at_a_time():
    A = independent_activations(300, seed=3)
    assert A.shape == (300, len(ACTIONS)) and A.tobytes() == independent_activations(300, seed=3).tobytes()
    assert A.min() >= 0 and A.max() < 2
    for both, (left, right) in BILATERAL.items():
        assert not A[:, action_index(both)].any()  # a two-sided action never moves both sides as one
        a, b = A[:, action_index(left)], A[:, action_index(right)]
        assert np.corrcoef(a, b)[0, 1] < 0.99  # the sides are not one source
        assert np.abs(a - b).max() > 0.1
    for name in INDEPENDENT_SOURCES:
        assert A[:, _columns(name)].max() > 0.05, name
    shift = A[:, _columns("jaw_shift")]
    assert not (shift[:, 0] * shift[:, 1]).any()  # the jaw shifts one way at a time
    assert np.abs(np.diff(A, axis=0)).max() < 0.6  # smooth at 30 frames/s


def test_sources_are_linearly_independent_at_the_dots(subject):
    """No source is a combination of the others: the 22 sources' displacements of the 16 dots
    (48 DOFs) at activation 0.5 have full rank, the weakest direction well above round-off."""
    from lipgen.subject.motion import simulate

    rows = []
    for name in INDEPENDENT_SOURCES:
        a = np.zeros(len(ACTIONS))
        a[_columns(name)[0]] = 0.5
        m = simulate(subject, a[None])
        rows.append((m.markers - m.rest_markers).ravel())
    s = np.linalg.svd(np.array(rows), compute_uv=False)
    assert len(s) == 22 and s[-1] / s[0] > 1e-3, s / s[0]


def _held(viseme):
    a = np.zeros(len(ACTIONS))
    for name, x in VISEMES[viseme].items():
        for col in BILATERAL.get(name, (name,)):
            a[action_index(col)] += x
    a[action_index("jaw_open")] *= JAW_GAIN
    return a


def test_jaw_opens_20_mm_on_an_open_vowel(subject):
    from lipgen.subject.motion import simulate

    m = simulate(subject, _held("AA")[None])
    lower = (m.markers - m.rest_markers)[0, m.mesh.marker_names.index("lower_mid")]
    assert np.linalg.norm(lower) >= 20.0 and lower[1] < -18.0  # down ...
    assert lower[2] < -2.0  # ... and back: the jaw rotates about its hinge


def test_speech_reaches_protrusion_of_8_mm(subject):
    A = independent_activations(600, seed=1)
    m = simulate_independent(subject, 600, 1, activations=A, rms_mm=0.0)
    z = (m.markers - m.rest_markers)[:, [0, 1], 2]  # the mid markers of both lips
    assert 8.0 <= z.max() <= 14.0


def test_residual_is_smooth_scaled_and_not_low_rank(subject):
    R = residual_motion(subject, 150, seed=2)
    at = _at_dots(subject, R)
    assert np.sqrt(np.mean(np.sum(at**2, axis=-1))) == pytest.approx(RESIDUAL_MM, rel=1e-9)
    s = np.linalg.svd(at.reshape(150, -1), compute_uv=False)
    share = np.cumsum(s**2) / np.sum(s**2)
    assert np.searchsorted(share, 0.99) + 1 >= 14  # 99 % of it needs 14 directions or more
    assert np.abs(np.diff(at, axis=0)).max() < 1.0  # mm per frame: smooth in time
    assert not residual_motion(subject, 20, seed=2, rms_mm=0.0).any()


def test_default_clip_meets_the_variance_target(subject):
    """10 modes learned from the first 140 frames of the default 150-frame clip (seed 0, not one
    of the development seeds 100-104 the residual was set on) hold 98.5-99.5 % of the variance
    (thesis: 99.2 %); the gestures of the easy preset hold more than 99.9 %."""
    from lipgen import Physics, lip_mesh
    from lipgen.fem import dofs
    from lipgen.modes.model import ModeModel
    from lipgen.subject.motion import random_activations, simulate

    mesh = lip_mesh(0)
    physics = Physics(mesh)

    def held(m):
        goals = (m.markers - m.rest_markers).reshape(150, -1)
        reach, _ = physics.reach(dofs(mesh.markers), goals)
        return float(ModeModel(10).fit(reach[:140], mesh=mesh).explained_variance_ratio_.sum())

    assert 0.985 <= held(simulate_independent(subject, 150, 0)) <= 0.995
    assert held(simulate(subject, random_activations(150, 0))) > 0.999


@pytest.mark.parametrize("kwargs, message", [
    ({"syllables_per_second": 12.0}, "impossible"),
    ({"jaw_gain": 3.0}, r"jaw_gain must be in \(0, 2\], got 3.0"),
    ({"n_frames": 0}, "n_frames must be >= 1, got 0"),
])
def test_activation_bad_input(kwargs, message):
    with pytest.raises(ValueError, match=message):
        independent_activations(**{"n_frames": 30, **kwargs})


def test_residual_bad_input(subject):
    with pytest.raises(ValueError, match=r"rms_mm must be in \[0, 5\] mm, got 9.0"):
        residual_motion(subject, 10, rms_mm=9.0)


def test_presets_choose_the_motion():
    from lipgen.dataset.settings import GenerateSettings

    assert GenerateSettings.from_preset("easy").motion_sources == "gestures"
    d = GenerateSettings.from_preset("default")
    assert d.motion_sources == "independent" and d.to_dict()["motion_sources"] == "independent"
    assert "motion_sources" not in GenerateSettings().to_dict()  # manifests before it are unchanged
    with pytest.raises(ValueError, match="motion_sources must be 'gestures' or 'independent', got 'x'"):
        GenerateSettings(motion_sources="x")
