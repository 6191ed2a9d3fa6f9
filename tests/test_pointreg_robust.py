"""Trimmed first-frame registration (pointreg robust=True) against missing dots and lures.

A synthetic lip layout (two lip arcs, inner corners, nose) is moved by a random similarity, its
lower lip dropped (an open mouth), three of its dots removed and four lure dots scattered between
the lips. The truth of every match is known.
"""

import numpy as np
import pytest

from lipgen.recon.pointreg import match_to_expected, register_nonrigid


def _layout() -> np.ndarray:
    a = np.linspace(0, np.pi, 7)
    upper = np.column_stack([60 * np.cos(a), -18 * np.sin(a) - 4])
    lower = np.column_stack([50 * np.cos(a[1:-1]), 20 * np.sin(a[1:-1]) + 4])
    inner = np.array([[-30, -2], [30, -2], [-30, 2], [30, 2.0]])
    return np.vstack([upper, lower, inner, [[0, -70.0]]])


def _case(seed: int, drop_px: float):
    rng = np.random.default_rng(seed)
    layout = _layout()
    th, s = rng.uniform(-0.1, 0.1), rng.uniform(0.9, 1.1)
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    true = s * layout @ R.T + rng.uniform(-4, 4, 2)
    low = layout[:, 1] > 3
    true[low] += s * np.array([0, drop_px]) * (1 - np.abs(layout[low, 0]) / 70)[:, None]
    true += rng.normal(0, 0.3, true.shape)
    keep = np.setdiff1d(np.arange(len(layout)), rng.choice(len(layout) - 1, 3, replace=False))
    dots = np.vstack([true[keep], rng.uniform([-55, -10], [55, 20], (4, 2))])
    want = np.full(len(layout), -1)
    want[keep] = np.arange(len(keep))
    return layout, dots, want


def _wrong_right(match, want):
    return int(((match >= 0) & (match != want)).sum()), int(((match >= 0) & (match == want)).sum())


def test_a_lure_taken_by_the_plain_registration_is_refused_by_the_trimmed_one():
    layout, dots, want = _case(8, 6.0)
    old_wrong, old_right = _wrong_right(match_to_expected(dots, layout, 6.0), want)
    new_wrong, new_right = _wrong_right(match_to_expected(dots, layout, 6.0, robust=True), want)
    assert old_wrong > 0                     # the case is one the plain registration gets wrong
    assert new_wrong == 0
    assert new_right >= old_right


@pytest.mark.parametrize("drop_px", [0.0, 10.0])
def test_trimmed_registration_makes_fewer_wrong_matches_over_many_layouts(drop_px):
    old = new = 0
    for seed in range(40):
        layout, dots, want = _case(seed, drop_px)
        old += _wrong_right(match_to_expected(dots, layout, 6.0), want)[0]
        new += _wrong_right(match_to_expected(dots, layout, 6.0, robust=True), want)[0]
    assert new < old


def test_trimmed_registration_is_exact_without_lures_or_missing_dots():
    rng = np.random.default_rng(3)
    layout = _layout()
    dots = 1.05 * layout + [3.0, -2.0]
    order = rng.permutation(len(dots))
    match, aligned = register_nonrigid(dots[order], layout, 6.0, robust=True)
    np.testing.assert_array_equal(order[match], np.arange(len(layout)))
    np.testing.assert_allclose(aligned, dots, atol=1e-9)


def _dense_hypotheses(monkeypatch, dots, expected, gate):
    """``pointreg._hypotheses`` as first written: every hypothesis against every dot, (H, P, k)."""
    from lipgen.recon import pointreg

    calls = []

    def dense(tree, d, moved, gate):
        calls.append(1)
        return np.abs(moved[:, :, None] - d[None, None, :]).min(axis=2)

    with monkeypatch.context() as m:
        m.setattr(pointreg, "_nearest_within", dense)
        return pointreg._hypotheses(dots, expected, gate), len(calls)


@pytest.mark.parametrize("seed", range(4))
def test_the_two_point_hypotheses_match_every_distance_measured(seed, monkeypatch):
    """The nearest dots come from a k-d tree, but the winner is the one the dense (H, P, k) distances
    give, bit for bit, with clutter, a duplicated dot (a tie) and dots far outside the gate."""
    from scipy.spatial import cKDTree

    from lipgen.recon import pointreg

    rng = np.random.default_rng(seed)
    layout, dots, _ = _case(seed, 6.0)
    clutter = rng.uniform(dots.min(0) - 40, dots.max(0) + 40, (150, 2))
    dots = np.vstack([dots, clutter, dots[:1], [[1e4, 1e4]]])
    want, n = _dense_hypotheses(monkeypatch, dots, layout, 3.0)
    assert n > 0 and np.array_equal(pointreg._hypotheses(dots, layout, 3.0), want)
    moved = (rng.normal(size=(50, len(layout))) * 30 + 1j * rng.normal(size=(50, len(layout))) * 30)
    d = dots[:, 0] + 1j * dots[:, 1]
    near = pointreg._nearest_within(cKDTree(dots), d, moved, 3.0)
    dense = np.abs(moved[:, :, None] - d[None, None, :]).min(axis=2)
    assert np.array_equal(near[dense < 3.0], dense[dense < 3.0])
    assert np.all(np.isinf(near[dense >= 3.0 * 1.01]))
    assert np.array_equal(pointreg._hypotheses(dots[:1], layout, 3.0), layout)  # one dot: no pair
