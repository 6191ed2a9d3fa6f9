"""The ``cycles`` benchmark suite runs (quick size) and reports its figures; timings are not asserted."""

import pytest

pytestmark = [pytest.mark.render, pytest.mark.blender]


def test_cycles_bench_suite_runs_quick():
    pytest.importorskip("bpy")
    pytest.importorskip("pyrender")
    from lipgen.bench import available_suites
    from lipgen.bench.cycles import run

    assert "cycles" in available_suites()
    res = run(quick=True)
    row = res["160x120"]
    assert set(row) == {"pyrender", "cycles_4"}
    assert row["pyrender"]["cpu_ratio_to_pyrender"] == 1.0
    for fig in row.values():
        assert fig["cpu_s_per_frame"] > 0 and fig["wall_s_per_frame"] > 0
    assert res["load_average_before"] and res["baseline"] == "pyrender"
