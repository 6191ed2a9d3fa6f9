"""Table 5.1 with utterance and subject splits over several subject seeds."""

import numpy as np
import pytest

from lipgen.experiments.table51_splits import ESTIMATORS, SPLITS, SplitSettings, mean_interval, run_splits


def test_mean_interval_is_scipys_t_interval():
    from scipy import stats

    v = np.array([1.0, 1.5, 0.7, 2.2, 1.1])
    m, lo, hi = mean_interval(v)
    ref = stats.t.interval(0.95, len(v) - 1, loc=v.mean(), scale=stats.sem(v))
    assert m == pytest.approx(v.mean()) and (lo, hi) == pytest.approx(ref, rel=1e-12)


@pytest.mark.slow
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


@pytest.mark.parametrize("kwargs, message", [
    ({"n_test": 5}, "n_test must be >= 10 consecutive test frames"),
    ({"seeds": (3, 3)}, r"2 or more distinct subject seeds.*\(3, 3\)"),
    ({"preset": "medium"}, "unknown preset 'medium'"),
])
def test_bad_settings(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SplitSettings(**kwargs)
