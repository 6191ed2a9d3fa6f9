"""Difficulty presets: one module, recorded, and ``easy`` reproduces the data before presets."""

import numpy as np
import pytest

from lipgen.dataset.layout import GenerateSettings
from lipgen.dataset.presets import PRESETS, FrameConditions, Preset, get_preset


def test_presets_group_subject_motion_and_image_conditions():
    assert set(PRESETS) == {"easy", "default", "hard"}
    for p in PRESETS.values():
        assert isinstance(p, Preset) and isinstance(p.image, FrameConditions)
    assert not PRESETS["easy"].subject.own_shape and PRESETS["default"].subject.own_shape
    assert PRESETS["hard"].subject.nonlinear_physics


def test_easy_settings_are_the_settings_before_presets():
    easy = GenerateSettings.from_preset("easy", frames=150, seed=0)
    plain = GenerateSettings()
    assert easy == plain and easy.to_dict() == plain.to_dict()  # the same manifest, byte for byte
    assert "preset" not in plain.to_dict() and "subject_seed" not in plain.to_dict()
    assert GenerateSettings.from_preset("default").to_dict()["preset"] == "default"


def test_default_and_hard_settings_and_overrides():
    d = GenerateSettings.from_preset("default", seed=3)
    assert d.subject_seed == 0 and d.truth_physics == "linear" and d.seed == 3
    h = GenerateSettings.from_preset("hard", subject_seed=9, noise=0.5)
    assert h.subject_seed == 9 and h.truth_physics == "layer" and h.noise == 0.5
    assert h.head_rotation_deg == PRESETS["hard"].motion.head_rotation_deg
    back = GenerateSettings.from_dict(h.to_dict())
    assert back == h


def test_easy_reproduces_the_figures_before_presets():
    """Figures measured with the code before this change (main at the restructure commit)."""
    from lipgen.experiments.table51_protocol import Table51Settings, make_subject, observe
    from lipgen.fem import Physics
    from lipgen.mesh.procedural import lip_mesh
    from lipgen.subject.motion import head_motion, random_activations

    subject = make_subject(Table51Settings(seed=2, preset="easy"))
    ob = observe(subject, Physics(lip_mesh(0)), random_activations(20, 2), head_motion(20, 2))
    assert np.mean(ob.goals**2) == pytest.approx(5.126438917823071, rel=1e-9)
    assert np.mean(ob.reach**2) == pytest.approx(3.4081405169555996, rel=1e-9)
    assert np.mean(ob.truth**2) == pytest.approx(3.6437065600201985, rel=1e-9)


def test_unknown_presets_and_misused_subject_seeds_are_refused():
    with pytest.raises(ValueError, match="unknown preset 'medium'; choose one of easy, default, hard"):
        get_preset("medium")
    with pytest.raises(ValueError, match="unknown preset"):
        GenerateSettings.from_preset("medium")
    with pytest.raises(ValueError, match="subject seed needs preset"):
        GenerateSettings.from_preset("easy", subject_seed=3)
    with pytest.raises(ValueError, match="truth_physics"):
        GenerateSettings(truth_physics="quadratic")
    with pytest.raises(ValueError, match=r"subject_seed must be a whole number in \[0, 4294967295\]"):
        GenerateSettings(subject_seed=-2)
    from lipgen.experiments.table51_protocol import Table51Settings

    with pytest.raises(ValueError, match="unknown preset"):
        Table51Settings(preset="impossible")
