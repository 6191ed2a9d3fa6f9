"""The demo command and the physics benchmark run end to end on small sizes."""

import subprocess
import sys

import numpy as np
import pytest

from lipgen.bench import physics as bench_physics
from lipgen.commands.demo import NAMED_FORCES, named_force


def _check_demo(returncode, stdout, stderr, folder):
    assert returncode == 0, stderr
    for name in ("physics_forces.png", "rest_state.png", "fig_2_2.png"):
        path = folder / "demo" / name
        assert path.stat().st_size > 10_000 and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert str(path) in stdout
    report = folder / "demo" / "report" / "report.md"
    assert str(report) in stdout and "| total before the report |" in report.read_text()
    for name in ("recon.npz", "model.npz"):
        assert (folder / "demo" / name).stat().st_size > 1000


def _run_demo(folder, *extra):
    # No timeout: how long this takes depends on the machine's load, not on lipgen.
    out = subprocess.run([sys.executable, "-m", "lipgen", "demo", "--out", str(folder), "--no-progress",
                          *extra], capture_output=True, text=True)
    return out.returncode, out.stdout, out.stderr


@pytest.mark.render
def test_small_demo_end_to_end(tmp_path, capsys):
    """The whole loop (pictures, dataset, reconstruction, modes, evaluation, report) on 17
    frames rendered by one process: what the default demo does, on a tenth of its frames (about
    the fewest whose 5 folds each leave the 11 training frames its 10 modes need). It runs the
    command line in this process (`lipgen demo` in a subprocess is the full demo's test): a new
    interpreter's imports cost about 2 s of CPU that say nothing more about the loop."""
    pytest.importorskip("cv2")
    from lipgen.cli import main

    status = main(["demo", "--out", str(tmp_path), "--no-progress", "--frames", "17", "--workers", "1"])
    out = capsys.readouterr()
    _check_demo(status, out.out, out.err, tmp_path)


@pytest.mark.slow(cover="tests/test_fem_demo_bench.py::test_small_demo_end_to_end")
@pytest.mark.render
def test_full_demo(tmp_path):
    """`lipgen demo` with its defaults (150 frames, 2 workers); `make test-slow` runs it."""
    _check_demo(*_run_demo(tmp_path), tmp_path)


def test_named_forces_reach_their_peak():
    import lipgen

    mesh = lipgen.lip_mesh(0)
    ph = lipgen.Physics(mesh)
    for name in NAMED_FORCES:
        U = ph.displace(named_force(mesh, name, 3.0, ph))
        assert np.linalg.norm(U, axis=1).max() == pytest.approx(3.0, rel=1e-9)


def test_physics_bench_resolution_0():
    row = bench_physics._one_resolution(0, quick=True, solvers=["superlu"], memory=False)
    assert row["nodes"] == 201 and row["residual_superlu"] < 1e-10
    assert row["dense"]["max_abs_difference_mm"] < 1e-9
    assert row["dense_inverse_over_factor"] > 0
