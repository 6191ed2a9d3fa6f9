"""The ``blender`` benchmark suite runs (quick sizes) and reports its figures; timings are not
asserted here (they belong to ``lipgen bench``)."""

import pytest
from blender_session import bpy_available


@pytest.mark.blender
@pytest.mark.skipif(not bpy_available(), reason="needs the pip bpy module")
def test_blender_bench_suite_runs_quick():
    from lipgen.bench import available_suites
    from lipgen.bench.blender import run

    assert "blender" in available_suites()
    out = run(quick=True)
    assert out["playback_res0"]["n_vertices"] == 201 and out["playback_res0"]["n_modes"] == 10
    assert out["playback_res2"]["per_frame_s"]["median_s"] > 0
    prev = out["preview_res2"]
    assert prev["update_s"]["median_s"] > 0 and prev["baseline_write_key_s"]["median_s"] > 0
