"""The demo command and the physics benchmark run end to end on small sizes."""

import subprocess
import sys

import numpy as np
import pytest

from lipgen.bench import physics as bench_physics
from lipgen.commands.demo import NAMED_FORCES, named_force


def test_demo_writes_pictures(tmp_path):
    out = subprocess.run([sys.executable, "-m", "lipgen", "demo", "--out", str(tmp_path)],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    for name in ("physics_forces.png", "rest_state.png", "fig_2_2.png"):
        path = tmp_path / "demo" / name
        assert path.stat().st_size > 10_000 and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert str(path) in out.stdout


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
