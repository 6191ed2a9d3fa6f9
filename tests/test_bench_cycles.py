"""The ``cycles`` benchmark suite runs (quick size) and reports its figures; timings are not asserted."""

import pytest

pytestmark = [pytest.mark.render, pytest.mark.blender]


@pytest.mark.slow(
    cover=(
        "tests/test_bench_cycles.py::test_the_bench_measures_one_round_of_its_baseline",
        "tests/test_cycles.py::test_cycles_draws_the_same_picture_as_pyrender[plain]",
    )
)
def test_cycles_bench_suite_runs_quick():
    pytest.importorskip("bpy")
    pytest.importorskip("pyrender")
    from lipgen.bench import available_suites
    from lipgen.bench.cycles import run

    assert "cycles" in available_suites()
    res = run(quick=True)
    _check_figures(res, {"pyrender", "cycles_4"})


def test_the_bench_measures_one_round_of_its_baseline():
    """The suite's measurement (what ``run(quick=True)`` calls) on its pyrender baseline alone, one
    round after the warm-up: the rounds, medians, ratios and load averages without Cycles' frames
    (a denoised Cycles frame costs seconds of CPU; Cycles' pictures are tested in test_cycles.py)."""
    pytest.importorskip("pyrender")
    from lipgen.bench.cycles import measure

    res = measure([(160, 120)], [], 1)
    assert res["rounds"] == 1
    _check_figures(res, {"pyrender"})


def _check_figures(res: dict, renderers: set) -> None:
    row = res["160x120"]
    assert set(row) == renderers
    assert row["pyrender"]["cpu_ratio_to_pyrender"] == 1.0
    for fig in row.values():
        assert fig["cpu_s_per_frame"] > 0 and fig["wall_s_per_frame"] > 0
    assert res["load_average_before"] and res["baseline"] == "pyrender"
