"""Table 5.1 with utterance and subject splits over several subject seeds."""

import numpy as np
import pytest

from lipgen.experiments.table51_splits import (
    ESTIMATORS,
    SPLITS,
    SplitSettings,
    mean_interval,
    paired_interval,
    run_splits,
)


def test_mean_interval_is_scipys_t_interval():
    from scipy import stats

    v = np.array([1.0, 1.5, 0.7, 2.2, 1.1])
    m, lo, hi = mean_interval(v)
    ref = stats.t.interval(0.95, len(v) - 1, loc=v.mean(), scale=stats.sem(v))
    assert m == pytest.approx(v.mean()) and (lo, hi) == pytest.approx(ref, rel=1e-12)


def test_paired_interval_is_scipys_paired_t_test_on_the_log_errors():
    """The interval excludes 1 exactly when scipy's paired t-test on log errors rejects at 5 %,
    and it does on errors that differ by a steady factor hidden under a large seed spread."""
    from scipy import stats

    rng = np.random.default_rng(7)
    scale = np.exp(rng.normal(0, 1.0, 6))  # seeds differ by e^±1: the unpaired intervals overlap
    a = scale * 1.3 * np.exp(rng.normal(0, 0.05, 6))
    b = scale * np.exp(rng.normal(0, 0.05, 6))
    g, lo, hi = paired_interval(a, b)
    res = stats.ttest_rel(np.log(a), np.log(b))
    ci = res.confidence_interval(0.95)
    assert (lo, hi) == pytest.approx((np.exp(ci.low), np.exp(ci.high)), rel=1e-12)
    assert g == pytest.approx(np.exp(np.mean(np.log(a / b))))
    assert 1 < lo < 1.3 < hi and res.pvalue < 0.05
    ma, la, ha = mean_interval(a)
    mb, lb, hb = mean_interval(b)
    assert la < hb and lb < ha  # unpaired: the intervals overlap
    g, lo, hi = paired_interval(b, b * np.exp([0.05, -0.05, 0.03, -0.03, 0.01, -0.01]))  # no steady factor
    assert g == pytest.approx(1.0) and lo < 1 < hi


@pytest.mark.slow(
    cover=(
        "tests/test_table51_splits.py::test_paired_interval_is_scipys_paired_t_test_on_the_log_errors",
        "tests/test_table51_pipeline.py::test_report_from_seed_records",
    )
)
def test_splits_on_two_small_subjects(tmp_path):
    """About 30 s of CPU (four subjects, the combined model's cross-validation): the slow set."""
    from lipgen.experiments.table51_splits import write_splits_report

    s = SplitSettings(seeds=(0, 1), n_train=60, n_modes=6, n_windows=1, lead_in=15, head=False)
    r = run_splits(s)
    assert [p["seed"] for p in r["per_seed"]] == [0, 1]
    for split in SPLITS:
        for row, cols in r["summary"][split].items():
            for col in ESTIMATORS:
                m, lo, hi = cols[col]["truth"]
                vals = [p[split][row][col]["truth"] for p in r["per_seed"]]
                assert m == pytest.approx(np.mean(vals)) and lo <= m <= hi
                if col != "full":  # (the full covariance of 60 frames overfits: it may not)
                    # learned from another utterance, the estimate beats predicting no motion
                    assert 0 < cols[col]["truth_relative"][0] < 1, (split, row, col)
    md = write_splits_report(r, tmp_path)
    text = open(md).read()
    assert "Utterance split" in text and "Subject split" in text and "(thesis: 9.4)" in text
    assert "Paired" in text and "at the hidden marker coordinates vs the measured markers" in text
    for split in SPLITS:
        assert all(len(p["windows"][split]) == 1 and p["windows"][split][0]["z_over_x"] > 0
                   and p["order_markers"][split] == p["windows"][split][0]["order_markers"] > 0
                   for p in r["per_seed"])
    for split in SPLITS:
        for row, pairs in r["paired"][split].items():
            assert len(pairs) == len(ESTIMATORS) * (len(ESTIMATORS) - 1) // 2
            g, lo, hi = pairs["modes/physics_force"]
            vals = [p[split][row]["modes"]["truth"] / p[split][row]["physics_force"]["truth"]
                    for p in r["per_seed"]]
            assert g == pytest.approx(np.exp(np.mean(np.log(vals)))) and lo <= g <= hi


@pytest.mark.parametrize("kwargs, message", [
    ({"n_test": 5}, "n_test must be >= 10 consecutive test frames"),
    ({"seeds": (3, 3)}, r"2 or more distinct subject seeds.*\(3, 3\)"),
    ({"preset": "medium"}, "unknown preset 'medium'"),
])
def test_bad_settings(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SplitSettings(**kwargs)


@pytest.mark.parametrize("a, b, message", [
    ([1.0, 2.0], [1.0, 2.0, 3.0], r"same seeds, got shapes \(2,\) and \(3,\)"),
    ([1.0, 0.0], [1.0, 2.0], "must be > 0"),
    ([1.0], [2.0], r"need 2 or more values"),
])
def test_paired_interval_bad_input(a, b, message):
    with pytest.raises(ValueError, match=message):
        paired_interval(a, b)


def test_window_orders_on_known_windows():
    """Windows whose order grows with their depth motion: rank correlation 1, counts and the top
    quartile's median read back."""
    from lipgen.experiments.table51_splits import window_orders

    z = np.array([0.5, 1.0, 2.0, 4.0, 3.0, 0.8, 6.0, 5.0])
    wins = [{"order_truth": 0.5 * v, "order_reach": -v, "z_over_x": v} for v in z]
    result = {"per_seed": [{"windows": {"utterance": wins[:4]}}, {"windows": {"utterance": wins[4:]}}]}
    w = window_orders(result, "utterance")
    assert w["n"] == 8 and w["above_1"] == {"truth": 4, "reach": 0}  # 0.5 z > 1: z in 3, 4, 5, 6
    assert w["spearman"]["truth"] == pytest.approx(1.0) and w["spearman"]["reach"] == pytest.approx(-1.0)
    assert w["top_quartile"]["truth"] == pytest.approx(0.5 * np.median([5.0, 6.0]))
    with pytest.raises(ValueError, match="need 4 or more test windows"):
        window_orders({"per_seed": [{"windows": {"utterance": wins[:3]}}]}, "utterance")


def test_marker_order_scores_only_the_hidden_marker_coordinates():
    """With an estimate of no motion, the x-y row's error is the mean square of the markers' z and
    the y-z row's that of their x; every other DOF is ignored."""
    from lipgen.experiments.table51_splits import _marker_order
    from lipgen.fem import dofs

    rng = np.random.default_rng(1)
    markers = np.array([3, 7, 11])
    U = rng.normal(size=(5, 20, 3))
    U[:, markers, 2] *= 3.0
    U[:, 15:] *= 100.0  # not markers: must not count
    zero = lambda y: np.zeros((len(y), 60))  # noqa: E731
    at = {"xy": (dofs(markers, "xy"), zero, dofs(markers, "z")),
          "yz": (dofs(markers, "yz"), zero, dofs(markers, "x"))}
    expect = np.mean(U[:, markers, 2] ** 2) / np.mean(U[:, markers, 0] ** 2)
    assert _marker_order(at, U) == pytest.approx(expect)
