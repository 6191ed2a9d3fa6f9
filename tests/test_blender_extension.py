"""Packaging of the Blender extension: manifest, validator, wheels, and the built zip installed
into a bare Blender that has nothing but bpy and numpy."""

import base64
import csv
import hashlib
import json
import os
import platform
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest
from blender_session import bpy_available

from lipgen.blender import packaging

ROOT = Path(__file__).resolve().parents[1]
needs_bpy = pytest.mark.skipif(not bpy_available(), reason="needs the pip bpy module (Blender's validator)")


@needs_bpy
def test_source_manifest_passes_blenders_validator():
    out = packaging.validate(ROOT / "blender_addon")
    assert "Success" in out


@needs_bpy
def test_validator_rejects_a_bad_manifest(tmp_path):
    bad = tmp_path / "addon"
    bad.mkdir()
    (bad / "__init__.py").write_text("")
    text = (ROOT / "blender_addon" / "blender_manifest.toml").read_text()
    (bad / "blender_manifest.toml").write_text(text.replace('type = "add-on"', 'type = "plugin"'))
    with pytest.raises(ValueError, match="validator rejected"):
        packaging.validate(bad)


def test_manifest_has_no_bl_info_and_uses_relative_imports():
    for p in (ROOT / "blender_addon").glob("*.py"):
        text = p.read_text()
        assert "bl_info" not in text, p
        assert "import blender_addon" not in text and "from blender_addon" not in text, p
    meta = tomllib.loads((ROOT / "blender_addon" / "blender_manifest.toml").read_text())
    assert meta["type"] == "add-on" and meta["blender_version_min"] >= "4.2.0"


def test_manifest_with_wheels_keeps_tables_and_parses():
    src = (ROOT / "blender_addon" / "blender_manifest.toml").read_text()
    text = packaging._manifest_with(src, ["a-1-py3-none-any.whl"], ["linux-x64"])
    meta = tomllib.loads(text)
    assert meta["wheels"] == ["./wheels/a-1-py3-none-any.whl"]
    assert meta["platforms"] == ["linux-x64"]
    assert meta["permissions"] == tomllib.loads(src)["permissions"]
    # Running it again replaces, never duplicates.
    again = tomllib.loads(packaging._manifest_with(text, ["b-2-py3-none-any.whl"], ["macos-arm64"]))
    assert again["wheels"] == ["./wheels/b-2-py3-none-any.whl"]


@pytest.mark.parametrize("name, platforms", [
    ("scipy-1.17.1-cp311-cp311-manylinux_2_27_x86_64.manylinux_2_28_x86_64.whl", {"linux-x64"}),
    ("scipy-1.17.1-cp311-cp311-win_amd64.whl", {"windows-x64"}),
    ("scipy-1.17.1-cp311-cp311-win_arm64.whl", {"windows-arm64"}),
    ("scipy-1.17.1-cp311-cp311-macosx_14_0_arm64.whl", {"macos-arm64"}),
    ("scipy-1.17.1-cp311-cp311-macosx_10_14_x86_64.whl", {"macos-x64"}),
    ("x-1-cp311-cp311-macosx_11_0_universal2.whl", {"macos-x64", "macos-arm64"}),
    ("tqdm-4.70.1-py3-none-any.whl", set(packaging.PLATFORMS)),
])
def test_wheel_platforms(name, platforms):
    assert packaging._blender_platform_of(name) == platforms


def test_pure_wheel_record_is_complete_and_correct(tmp_path):
    import lipgen

    whl = packaging.write_pure_wheel(Path(lipgen.__file__).parent, tmp_path, "lipgen", "9.9",
                                     ["scipy==1"])
    with zipfile.ZipFile(whl) as zf:
        names = set(zf.namelist())
        rows = list(csv.reader(zf.read("lipgen-9.9.dist-info/RECORD").decode().splitlines()))
        assert {r[0] for r in rows} == names
        for path, digest, size in rows:
            if path.endswith("RECORD"):
                continue
            data = zf.read(path)
            want = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
            assert digest == "sha256=" + want and int(size) == len(data)
        assert "Requires-Dist: scipy==1" in zf.read("lipgen-9.9.dist-info/METADATA").decode()
    assert "lipgen/blender/modebasis.py" in names and "lipgen/__init__.py" in names
    assert not any("__pycache__" in n for n in names)
    # pip accepts it.
    run = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps",
                          "--no-index", "--target", str(tmp_path / "t"), str(whl)],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert (tmp_path / "t" / "lipgen" / "blender" / "forces.py").is_file()


@needs_bpy
@pytest.mark.skipif(not (sys.platform == "linux" and platform.machine() == "x86_64"),
                    reason="installs the linux-x64 zip")
@pytest.mark.slow(cover=("tests/test_blender_extension.py::test_source_manifest_passes_blenders_validator",
                         "tests/test_blender_extension.py::test_manifest_with_wheels_keeps_tables_and_parses",
                         "tests/test_blender_extension.py::test_pure_wheel_record_is_complete_and_correct"))
def test_built_zip_validates_installs_and_works_in_a_bare_blender(tmp_path):
    # The build downloads the scipy wheel once (into the shared cache) and then works offline.
    out = subprocess.run([sys.executable, "-m", "lipgen", "blender-extension", "--out",
                          str(tmp_path / "dist"), "--platform", "linux-x64"],
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert "valid" in out.stdout
    zip_path = tmp_path / "dist" / "lipgen-0.1.0-linux_x64.zip"
    packaging.validate(zip_path)
    with zipfile.ZipFile(zip_path) as zf:
        meta = tomllib.loads(zf.read("blender_manifest.toml").decode())
        wheels = [Path(w).name for w in meta["wheels"]]
        assert any(w.startswith("lipgen-") for w in wheels) and any(w.startswith("scipy-") for w in wheels)
        assert not any(w.startswith("numpy-") for w in wheels), "Blender ships numpy"
        assert all(f"wheels/{w}" in zf.namelist() for w in wheels)
        assert "_bench_worker.py" not in zf.namelist(), "the benchmark worker is not shipped"
    # A bare interpreter: only bpy and numpy on the path, a fresh Blender user folder.
    import importlib.util

    site = tmp_path / "site"
    site.mkdir()
    for name in ("bpy", "numpy", "numpy.libs"):
        spec_dir = Path(importlib.util.find_spec("numpy").origin).parents[1] / name
        if name == "bpy":
            spec_dir = Path(importlib.util.find_spec("bpy").origin).parent
        if spec_dir.exists():
            (site / name).symlink_to(spec_dir)
    home = tmp_path / "home"
    home.mkdir()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "BLENDER"))}
    env.update(HOME=str(home), BLENDER_USER_RESOURCES=str(home / "blender"))
    probe = Path(__file__).with_name("bpy_install_probe.py")
    result = tmp_path / "probe.json"
    run = subprocess.run([sys.executable, "-I", "-S", str(probe), str(site), str(zip_path), str(result)],
                         capture_output=True, text=True, env=env, cwd=tmp_path)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    got = json.loads(result.read_text())
    assert got["install"] == ["FINISHED"]
    for mod in ("lipgen", "scipy"):  # imported from the extension's own wheels, not this venv
        assert str(home) in got[mod], got
    assert got["addon_modules"] == ["bl_ext.user_default.lipgen"]
    assert got["force_max_dev_mm"] < 1e-5, got
    assert "bpy" in got["pxr"], got  # Blender's own USD module
    from lipgen.usd.export import read_animation, validate

    assert [str(i) for i in validate(got["usd"]) if i.is_error] == []
    assert read_animation(got["usd"]).points.shape == (3, 201, 3)
