"""The Table 5.1 experiment, on a small run: it completes, writes its report and is consistent."""

import json

import numpy as np
import pytest

from lipgen.cli import main
from lipgen.experiments.table51 import COLUMNS, Table51Settings, observation_rows, run_table51
from lipgen.experiments.table51_report import write_report


@pytest.fixture(scope="module")
def small():
    settings = Table51Settings(n_frames=60, n_train=50, n_modes=6, seed=1, max_modes_curve=8, oos_frames=12,
                               oos_realisations=2)
    return run_table51(settings)


def test_small_run_is_consistent(small):
    assert 0.9 < small["variance_captured"] <= 1.0
    assert small["mm_per_unit"] == pytest.approx(72.0 / 2.83)
    assert list(small["table"]) == list(observation_rows(small["_mesh"]))
    for row in small["table"].values():
        for col in COLUMNS:
            assert np.isfinite(row[col]["reach"]) and row[col]["reach"] >= 0
            # The model cannot be closer to the truth than its own least-strain fields allow.
            assert row[col]["truth"] > 1e-6
    # On noise-free, in-span test fields the full sample covariance (the exact second moments of
    # the training fields) predicts the least-strain reference at least as well as 6 modes.
    xyz8 = small["table"]["xyz (8 points)"]
    assert xyz8["full"]["reach"] <= xyz8["modes"]["reach"]
    curve = small["modes_curve"]
    assert curve["k"] == list(range(1, 9)) and len(curve["xy (16 points)"]["truth"]) == 8
    for sel in (small["selection"], small["outside_span"]["selection"]):
        # Noise-free markers: the choice from the training fields finds (almost) no noise.
        assert sel["kind"] in ("force", "energy") and sel["residual_share"] > 0
        assert sel["noise_variance"] < 1e-3
        assert sel["by_kind"][sel["kind"]]["log_likelihood"] == sel["log_likelihood"]


def test_report_and_command(small, tmp_path):
    report = write_report(small, tmp_path / "a")
    text = report.read_text()
    assert "Variance captured by 6 modes" in text and "units²" in text
    assert "cross-validated marginal likelihood" in text and "Over 2 realisations" in text
    ratios = small["outside_span"]["realisations"].values()
    assert all(len(r["learned"]) == len(r["physics"]) == 2 for r in ratios)
    assert text.count(" both: best learned-only ") == 3  # the verdict of each row outside the span
    for name in ("modes.png", "error_vs_modes.png", "outside_span.png", "table51.json"):
        assert (tmp_path / "a" / name).stat().st_size > 1000
    assert json.loads((tmp_path / "a" / "table51.json").read_text())[0]["settings"]["n_modes"] == 6
    with pytest.raises(ValueError, match="n_modes < n_train < n_frames"):
        Table51Settings(n_frames=20, n_train=30)
    with pytest.raises(ValueError, match="unknown action 'grin'"):
        Table51Settings(held_out_test=("grin",))
    bad = ["experiment", "table51", "--frames", "10", "--train", "12", "--out", str(tmp_path / "b")]
    assert main(bad) == 1
