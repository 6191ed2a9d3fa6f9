"""The motion statistics behind Table 5.1's x-y / y-z order (lipgen.experiments.table51_kinematics)."""

import numpy as np
import pytest

from lipgen.experiments.table51_kinematics import (
    SOURCE_GROUPS,
    conditional_variance,
    dot_motion,
    lip_measures,
    split_errors,
    view_statistics,
)


def test_conditional_variance_is_the_gaussian_closed_form():
    """var(b | a) = var(b) (1 - rho²) for two jointly Gaussian DOFs; a block is its Schur complement."""
    sa, sb, rho = 2.0, 3.0, 0.6
    cov = np.array([[sa**2, rho * sa * sb], [rho * sa * sb, sb**2]])
    assert conditional_variance(cov, np.array([0]), np.array([1])) == pytest.approx(sb**2 * (1 - rho**2))
    rng = np.random.default_rng(0)
    M = rng.normal(size=(5, 5))
    C = M @ M.T
    o, h = np.array([0, 2, 3]), np.array([1, 4])
    schur = C[np.ix_(h, h)] - C[np.ix_(h, o)] @ np.linalg.solve(C[np.ix_(o, o)], C[np.ix_(o, h)])
    assert conditional_variance(C, o, h) == pytest.approx(np.trace(schur) / 2)


def _synthetic(F=4000, P=16, seed=0):
    """z an exact linear function of the frontal view (of y), x independent of the profile: the
    frontal view predicts everything, the profile nothing of x."""
    rng = np.random.default_rng(seed)
    D = np.zeros((F, P, 3))
    D[:, :, 1] = rng.normal(size=(F, P)) @ rng.normal(size=(P, P)) * 0.3
    D[:, :, 0] = rng.normal(scale=1.5, size=(F, P))
    D[:, :, 2] = D[:, :, 1] @ rng.normal(scale=0.5, size=(P, P))
    return D


def test_view_statistics_find_the_predictable_and_the_hidden_axis():
    D = _synthetic()
    v = view_statistics(D)
    assert v["var"]["x"] == pytest.approx(2.25, rel=0.05)
    assert v["xy"]["residual"] < 1e-9 and v["xy"]["r2"] == pytest.approx(1.0)
    assert v["yz"]["residual"] == pytest.approx(v["var"]["x"], rel=0.02)  # x is independent of y-z
    assert v["yz"]["r2"] == pytest.approx(0.0, abs=0.02)
    assert v["ratio"] < 1e-6


def test_split_errors_score_held_out_frames():
    D = _synthetic(F=600)
    e = split_errors(D, n_train=500)
    assert e["xy"] < 1e-9  # z is exactly linear in x-y: any covariance of enough frames finds it
    assert e["yz"] == pytest.approx(2.25, rel=0.3)  # nothing of x is predictable: about its variance
    e10 = split_errors(D, n_train=500, n_modes=10)
    assert e10["yz"] > 1.0
    with pytest.raises(ValueError, match="n_train must be in"):
        split_errors(D, n_train=600)


def test_lip_measures_read_width_opening_and_protrusion():
    names = ("upper_mid", "lower_mid", "corner_left", "corner_right")
    rest = np.array([[0, 6, 3], [0, -7, 3], [27, 0, -10], [-27, 0, -10]], float)
    t = np.linspace(0, 1, 50)
    D = np.zeros((50, 4, 3))
    D[:, 2, 0], D[:, 3, 0] = -3 * t, 3 * t  # the corners drawn in by 6 mm in all
    D[:, 0, 2] = 5 * t  # while the upper lip protrudes by 5 mm
    D[:, 1, 1] = -10 * t * (1 - t)  # and the mouth opens and closes
    m = lip_measures(D, rest, names)
    assert m["width"][-1] == pytest.approx(-6.0) and m["protrusion_upper"][-1] == pytest.approx(5.0)
    assert m["opening"].max() == pytest.approx(10 * 0.25, rel=0.01)
    assert m["corr"]["protrusion_width"] == pytest.approx(-1.0)
    assert m["ranges"]["width"] == pytest.approx(0.9 * 6.0, rel=1e-6)


def test_dot_motion_drops_source_groups():
    """With every source group and the residual switched off the dots stay at rest; one group off
    changes the motion; unknown groups are refused by name."""
    full = dot_motion(300, 12)
    assert full.shape == (12, 16, 3) and np.abs(full).max() > 0.1
    none = dot_motion(300, 12, drop=tuple(SOURCE_GROUPS))
    assert np.abs(none).max() < 1e-9
    assert not np.allclose(dot_motion(300, 12, drop=("protrusion",)), full)
    with pytest.raises(ValueError, match=r"unknown source group\(s\) \['lips'\]"):
        dot_motion(300, 12, drop=("lips",))


def test_view_statistics_bad_input():
    message = r"D must be \(F, P, 3\) displacements with F >= 3, got shape \(10, 16\)"
    with pytest.raises(ValueError, match=message):
        view_statistics(np.zeros((10, 16)))


def test_default_subject_moves_like_published_lip_kinematics():
    """The default subject's speech against published lip kinematics (see
    renders/examples/table51_kinematics): rounding narrows the mouth as it protrudes the lips
    (protrusion and width anti-correlated across frames); protrusion also comes with a wide
    opening (/ʃ/: Toda et al. 2003; lip separation and protrusion rise together over consonants:
    Westbury, Severson & Hashi 1999), so it is not a function of the width alone."""
    from lipgen.experiments.table51_protocol import Table51Settings, make_subject
    from lipgen.subject.inkdots import dot_positions

    subject = make_subject(Table51Settings(seed=301, preset="default"))
    D = dot_motion(301, 600, subject=subject)
    rest = dot_positions(subject.dots, subject.mesh.faces, subject.mesh.vertices)
    m = lip_measures(D, rest, subject.mesh.marker_names)
    assert -0.9 < m["corr"]["protrusion_width"] < -0.3
    assert m["corr"]["protrusion_opening"] > 0.0
    assert 5.0 < m["ranges"]["protrusion_upper"] < 12.0 and 8.0 < m["ranges"]["width"] < 20.0
