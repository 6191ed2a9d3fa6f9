"""generate refuses a truth motion the machine cannot hold, before the physics runs and before any write."""

import pytest

from lipgen.cli import main
from lipgen.dataset import footprint
from lipgen.dataset.footprint import (
    FIXED_BYTES,
    PEAK_BYTES_PER_VERTEX_FRAME,
    check_motion_memory,
    motion_peak_bytes,
)
from lipgen.errors import DatasetError


def test_estimate_grows_with_frames_vertices_and_workers():
    assert motion_peak_bytes(0, 750) == FIXED_BYTES
    one = motion_peak_bytes(1000, 750) - FIXED_BYTES
    assert one == 1000 * 750 * PEAK_BYTES_PER_VERTEX_FRAME + 1000 * 750 * 24
    assert motion_peak_bytes(2000, 750) - FIXED_BYTES == 2 * one
    assert motion_peak_bytes(1000, 750, workers=3) - motion_peak_bytes(1000, 750) == 2 * 1000 * 750 * 24


def test_simulated_motion_stays_under_the_estimate():
    """The estimate is an upper bound of the measured peak (tracemalloc) on a short clip."""
    import tracemalloc

    from lipgen.dataset.settings import GenerateSettings
    from lipgen.dataset.simulation import simulate_motion

    s = GenerateSettings.from_preset("default", frames=120)
    tracemalloc.start()
    try:
        m = simulate_motion(s)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    n = m.vertices.shape[1]
    assert peak <= motion_peak_bytes(120, n)
    assert peak / (120 * n) > 100  # the per-vertex-frame figure is of the right size, not padding


def test_refused_with_the_need_the_free_and_the_fix():
    want = (r"--frames 100000 at subject resolution 4 \(44976 vertices\) needs about .* GB .* 1\.0 GB is "
            r"free; generate at most about \d+ frames")
    with pytest.raises(DatasetError, match=want):
        check_motion_memory(100000, 4, available=1 << 30)
    assert check_motion_memory(10, 1, available=1 << 30) == motion_peak_bytes(10, 750)


def test_generate_refuses_before_the_physics_and_writes_nothing(tmp_path, capsys, monkeypatch):
    import lipgen.dataset.generate as gen

    monkeypatch.setattr(footprint, "available_bytes", lambda: 200 << 20)

    def ran(*a, **k):
        raise AssertionError("the truth physics ran before the memory check")

    monkeypatch.setattr(gen, "simulate_motion", ran)
    out = tmp_path / "big"
    status = main(["generate", "--frames", "5000", "--subject-resolution", "2", "--out", str(out),
                   "--no-progress"])
    assert status == 1
    err = capsys.readouterr().err
    assert "--frames 5000" in err and "GB is free" in err and "nothing was written" in err
    assert not out.exists()
