"""The shared plumbing: atomic writes, versioned files, argument checks, the CLI."""

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lipgen import ModelFileError
from lipgen._io import atomic_path, load_npz, save_npz
from lipgen._validate import as_float_array, as_index_array
from lipgen.bench import run_benchmarks
from lipgen.bench.measure import growth_exponent


def test_npz_roundtrip_and_schema(tmp_path):
    p = tmp_path / "m.npz"
    save_npz(p, "thing", 3, {"a": np.arange(4.0), "names": np.array(["x", "y"])})
    out = load_npz(p, "thing", 3, required=("a",))
    assert np.array_equal(out["a"], np.arange(4.0)) and list(out["names"]) == ["x", "y"]
    with pytest.raises(ModelFileError, match="schema version 3"):
        load_npz(p, "thing", 4)
    with pytest.raises(ModelFileError, match="not a 'other'"):
        load_npz(p, "other", 3)
    with pytest.raises(ModelFileError, match="missing field"):
        load_npz(p, "thing", 3, required=("b",))


def test_corrupt_npz_is_named(tmp_path):
    p = tmp_path / "bad.npz"
    p.write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(ModelFileError, match="corrupt or truncated"):
        load_npz(p, "thing", 1)


def test_atomic_path_leaves_destination_on_failure(tmp_path):
    dest = tmp_path / "out.txt"
    dest.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_path(dest) as tmp:
            tmp.write_text("half")
            raise RuntimeError("killed")
    assert dest.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.txt"]


def test_validation_messages_name_value_and_shape():
    with pytest.raises(ValueError, match=r"forces must have shape \(\*, 3\), got \(4, 2\)"):
        as_float_array(np.zeros((4, 2)), "forces", (None, 3))
    with pytest.raises(ValueError, match=r"non-finite.*index \(1, 2\)"):
        as_float_array([[0, 0, 0], [0, 0, np.nan]], "forces", (None, 3))
    with pytest.raises(ValueError, match=r"out of range \[0, 5\)"):
        as_index_array([1, 7], "anchors", 5)
    with pytest.raises(ValueError, match="repeats"):
        as_index_array([1, 1], "dofs", 5, unique=True)


def test_growth_exponent_recovers_power_law():
    n = np.array([10, 100, 1000])
    assert growth_exponent(n, 3 * n**1.5) == pytest.approx(1.5)


def test_bench_rejects_unknown_suite(tmp_path):
    with pytest.raises(ValueError, match="unknown benchmark suite"):
        run_benchmarks(tmp_path / "b.json", suites=["nope"])


def test_cli_help_lists_commands():
    out = subprocess.run([sys.executable, "-m", "lipgen", "--help"], capture_output=True, text=True)
    assert out.returncode == 0 and "bench" in out.stdout


def test_cli_bench_writes_machine_info(tmp_path):
    out = tmp_path / "b.json"
    run_benchmarks(out, suites=[])
    data = json.loads(Path(out).read_text())
    assert data["machine"]["python"] and "numpy" in data["machine"]["versions"]


@pytest.mark.parametrize("bad", [0, 65, -1, True, 2.0, "2", None])
def test_check_workers_names_the_bad_value(bad):
    from lipgen._validate import check_workers

    want = r"workers must be a whole number in \[1, 64\], got " + re.escape(repr(bad))
    with pytest.raises(ValueError, match=want):
        check_workers(bad)


def test_check_workers_keeps_whole_numbers():
    from lipgen._validate import check_workers

    assert [check_workers(n) for n in (1, 64, np.int64(3))] == [1, 64, 3]
