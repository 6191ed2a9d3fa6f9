"""Style is checked in CI: ruff over the package, the add-on and the tests."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_ruff_clean():
    ruff = shutil.which("ruff") or str(Path(sys.executable).with_name("ruff"))
    if not Path(ruff).exists():
        pytest.skip("ruff is not installed")
    targets = [str(ROOT / d) for d in ("lipgen", "tests", "blender_addon") if (ROOT / d).exists()]
    out = subprocess.run([ruff, "check", "--no-cache", *targets], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr


def test_core_never_imports_bpy():
    offenders = [str(p.relative_to(ROOT)) for p in (ROOT / "lipgen").rglob("*.py")
                 if any(line.lstrip().startswith(("import bpy", "from bpy"))
                        for line in p.read_text().splitlines())]
    assert not offenders, f"the core must not import bpy: {offenders}"
