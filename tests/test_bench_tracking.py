"""The tracking bench: registered, its ratios are the ratios of what it measured, and a real quick run."""

import pytest


def test_the_suite_is_registered():
    from lipgen.bench import available_suites

    assert available_suites()["tracking"] == "lipgen.bench.tracking"


def test_the_ratios_are_of_the_measured_seconds(monkeypatch):
    import lipgen.dataset.generate as gen
    from lipgen.bench import tracking

    made = []
    monkeypatch.setattr(gen, "generate", lambda path, settings, progress: made.append(settings))
    runs = {False: {"tracking_cpu_s": 2.0, "calibration_cpu_s": 7.0, "accepted_share": 0.9},
            True: {"tracking_cpu_s": 3.0, "calibration_cpu_s": 0.1, "accepted_share": 0.95}}
    monkeypatch.setattr(tracking, "_reconstruct", lambda path, cross_check: runs[cross_check])
    monkeypatch.setattr(tracking, "_blob_seconds", lambda dataset: 0.5)
    monkeypatch.setattr("lipgen.dataset.Dataset", lambda path: path)
    out = tracking.run(True)
    assert made[0].frames == 10 and made[0].preset == "default" and made[0].calib_frames == 6
    assert out["cpu_s_per_frame"] == {"opencv_blobs": 0.05, "track_once": 0.2, "track_cross_checked": 0.3}
    assert out["once_over_opencv_blobs"] == pytest.approx(4.0)
    assert out["cross_checked_over_opencv_blobs"] == pytest.approx(6.0)
    assert out["cross_checked_over_once"] == pytest.approx(1.5)
    assert out["calibration_cpu_s"] == 7.0        # the first run's: it calibrated, the second reused it
    assert out["accepted_share"] == {"once": 0.9, "cross_checked": 0.95}


@pytest.mark.slow(cover="tests/test_bench_tracking.py::test_the_ratios_are_of_the_measured_seconds")
def test_a_quick_run_measures_both_runs_and_the_baseline():
    from lipgen.bench import tracking

    out = tracking.run(True)
    per = out["cpu_s_per_frame"]
    assert 0 < per["opencv_blobs"] < per["track_once"] < per["track_cross_checked"]
    assert out["cross_checked_over_once"] > 1 and out["calibration_cpu_s"] > 0
    assert all(0.5 < s <= 1 for s in out["accepted_share"].values())
