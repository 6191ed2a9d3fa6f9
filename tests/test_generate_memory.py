"""generate refuses a truth motion the machine cannot hold, before the physics runs and before any write."""

import pytest

from lipgen.cli import main
from lipgen.dataset import footprint
from lipgen.dataset.footprint import BYTES_PER_VERTEX_FRAME, FIXED_MB, check_motion_memory, motion_peak_bytes
from lipgen.errors import DatasetError


def test_estimate_grows_with_frames_and_takes_the_larger_of_physics_and_rendering():
    fixed = FIXED_MB["linear"][1] << 20
    assert motion_peak_bytes(0, 750) == fixed
    assert motion_peak_bytes(1000, 750) - fixed == 1000 * 750 * BYTES_PER_VERTEX_FRAME
    assert motion_peak_bytes(1000, 750, 1, "layer") - motion_peak_bytes(1000, 750) == (170 - 20) << 20
    # 20 workers each holding the vertices outweigh the physics
    assert motion_peak_bytes(10**5, 750, workers=20) == 24 * 10**5 * 750 * 21


def _traced_peak(frames: int) -> int:
    """Bytes the truth physics of ``frames`` frames allocates at its peak over what was held before
    (numpy's arrays are traced; the sparse factorisations' C memory is not: the fixed part)."""
    import tracemalloc

    from lipgen.dataset.settings import GenerateSettings
    from lipgen.dataset.simulation import simulate_motion

    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    simulate_motion(GenerateSettings.from_preset("default", frames=frames))
    return tracemalloc.get_traced_memory()[1] - base


def test_the_per_frame_figure_bounds_the_measured_slope():
    """The traced peak of the truth physics at 20 and 220 frames, after a first call (its caches): its slope
    per vertex and frame is under the estimate's and of its size (not padding), and the whole under it."""
    import tracemalloc

    tracemalloc.start()
    try:
        _traced_peak(5)
        lo, hi = _traced_peak(20), _traced_peak(220)
    finally:
        tracemalloc.stop()
    slope = (hi - lo) / (200 * 750)
    assert 0.4 * BYTES_PER_VERTEX_FRAME < slope <= BYTES_PER_VERTEX_FRAME
    assert hi <= motion_peak_bytes(220, 750)


def test_refused_with_the_need_the_free_and_the_fix():
    want = (r"100000 frames at subject resolution 4 \(44976 vertices, linear truth\) need about .* GB .* "
            r"4\.0 GB is free: at most about \d+ frames fit")
    with pytest.raises(DatasetError, match=want):
        check_motion_memory(100000, 4, available=4 << 30)
    with pytest.raises(DatasetError, match="no length fits at this subject resolution"):
        check_motion_memory(100, 4, available=1 << 30)   # under the physics' fixed 2.1 GB
    assert check_motion_memory(10, 1, available=1 << 30) == motion_peak_bytes(10, 750)


def test_the_check_can_be_switched_off(monkeypatch):
    monkeypatch.setenv(footprint.MEMORY_CHECK_ENV, "off")
    assert check_motion_memory(100000, 4, available=1 << 30) > 1 << 30


def test_a_cgroup_limit_lowers_what_is_free(tmp_path, monkeypatch):
    import builtins

    files = {"/proc/meminfo": "MemTotal: 100 kB\nMemAvailable: 8388608 kB\n",
             "/sys/fs/cgroup/memory.max": str(3 << 30), "/sys/fs/cgroup/memory.current": str(1 << 30)}
    real = builtins.open

    def fake(path, *a, **k):
        if str(path) in files:
            p = tmp_path / str(path).replace("/", "_")
            p.write_text(files[str(path)])
            return real(p, *a, **k)
        if str(path).startswith("/sys/fs/cgroup"):
            raise FileNotFoundError(path)
        return real(path, *a, **k)

    monkeypatch.setattr(builtins, "open", fake)
    assert footprint.available_bytes() == 2 << 30          # the cgroup's room, not the host's 8 GB
    files["/sys/fs/cgroup/memory.max"] = "max"
    assert footprint.available_bytes() == 8 << 30


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
    assert "5000 frames" in err and "GB is free" in err and "Nothing was written" in err
    assert not out.exists()
