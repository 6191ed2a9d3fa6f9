"""Build the installable Blender extension: the add-on, a lipgen wheel and its dependencies' wheels.

Blender 4.2+ installs an extension from a zip whose ``blender_manifest.toml`` lists bundled
wheels; it unpacks them into its own site-packages. Blender ships numpy, so numpy is not
bundled. scipy has one wheel per platform, so each platform gets its own zip (Blender's
``--split-platforms``). The zips are built and checked by Blender's own extension tool
(``blender_ext.py``, the code behind ``blender --command extension build/validate``), which the
pip ``bpy`` module carries; a ``blender`` executable can be used instead.
"""

from __future__ import annotations

import base64
import csv
import hashlib
import importlib.util
import io
import logging
import os
import shutil
import subprocess
import sys
import tomllib
import zipfile
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

from lipgen.errors import MissingDependencyError

__all__ = ["PLATFORMS", "BUNDLED", "PYTHON_VERSION", "ExtensionBuild", "build_extension",
           "find_validator", "validate", "write_pure_wheel", "addon_source", "shipped_files"]

log = logging.getLogger(__name__)

PYTHON_VERSION = "3.11"
"""Blender 4.2 to 5.0 run Python 3.11."""

PLATFORMS: dict[str, tuple[str, ...]] = {
    "linux-x64": ("manylinux_2_28_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64"),
    "linux-arm64": ("manylinux_2_28_aarch64", "manylinux_2_17_aarch64", "manylinux2014_aarch64"),
    "windows-x64": ("win_amd64",),
    "windows-arm64": ("win_arm64",),
    "macos-arm64": ("macosx_14_0_arm64", "macosx_12_0_arm64", "macosx_11_0_arm64"),
    "macos-x64": ("macosx_12_0_x86_64", "macosx_10_14_x86_64", "macosx_10_9_x86_64"),
}
"""Blender platform name -> pip platform tags to try, best first."""

BUNDLED: tuple[str, ...] = ("scipy", "tqdm", "trimesh")
"""lipgen's run-time dependencies the add-on needs, besides numpy (Blender's own). matplotlib
and pillow serve reports and renders only, which the add-on does not use."""


@dataclass(frozen=True)
class ExtensionBuild:
    """What :func:`build_extension` made."""

    zips: dict[str, Path]
    """Blender platform -> built zip."""
    skipped: dict[str, str]
    """Blender platform -> why it was left out (no wheel for it)."""
    wheels: tuple[str, ...]
    """Every bundled wheel file name."""


def addon_source() -> Path:
    """The ``blender_addon`` folder of the lipgen source tree this package runs from."""
    here = Path(__file__).resolve().parents[2] / "blender_addon"
    if not (here / "blender_manifest.toml").is_file():
        raise FileNotFoundError(
            f"no blender_addon/ beside the lipgen package ({here}); build the extension from a "
            "lipgen source checkout, or pass --source DIR")
    return here


def find_validator() -> Path:
    """Blender's extension tool ``blender_ext.py`` inside the installed pip ``bpy`` module.

    Found without importing bpy (which is large and has global state).
    """
    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        raise MissingDependencyError(
            "building the Blender extension needs Blender's extension tool, shipped in the pip "
            "'bpy' module: pip install 'lipgen[blender]' (bpy==5.0.1, Python 3.11), or pass "
            "--blender /path/to/blender")
    root = Path(spec.origin).parent
    found = sorted(root.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not found:
        raise MissingDependencyError(f"the bpy module at {root} has no "
                                     "scripts/addons_core/bl_pkg/cli/blender_ext.py")
    return found[-1]


def _tool_command(blender: str | None) -> list[str]:
    if blender:
        return [blender, "--factory-startup", "--background", "--command", "extension"]
    return [sys.executable, str(find_validator())]


def validate(path: str | os.PathLike, blender: str | None = None) -> str:
    """Run Blender's extension validator on a folder or zip; return its output.

    Raises
    ------
    ValueError
        If the validator rejects it (the message carries the validator's own words).
    """
    cmd = [*_tool_command(blender), "validate", str(path)]
    run = subprocess.run(cmd, capture_output=True, text=True)  # no timeout: its time is the load's
    out = (run.stdout + run.stderr).strip()
    if run.returncode != 0 or "Success" not in out:
        raise ValueError(f"Blender's extension validator rejected {path}: {out}")
    return out


def _record_hash(data: bytes) -> str:
    return "sha256=" + base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()


SHIPPED_SUFFIXES = (".py",)
"""What a wheel of a package folder holds: the modules of its (sub)packages, nothing else."""


def shipped_files(package_dir: str | os.PathLike) -> list[Path]:
    """The files a wheel of ``package_dir`` ships: the ``.py`` modules of the package and of every
    subpackage (a folder with ``__init__.py``), listed, not globbed. Stray files (notes, data,
    temporaries, caches, symlinks) and folders that are not packages stay out."""
    root = Path(package_dir)
    if not (root / "__init__.py").is_file():
        raise ValueError(f"{root} is not a Python package (no __init__.py)")
    out, todo = [], [root]
    while todo:
        pkg = todo.pop()
        for p in sorted(pkg.iterdir()):
            if p.is_symlink() or p.name.startswith("."):
                continue
            if p.is_dir() and (p / "__init__.py").is_file() and p.name != "__pycache__":
                todo.append(p)
            elif p.is_file() and p.suffix in SHIPPED_SUFFIXES:
                out.append(p)
    return sorted(out)


def write_pure_wheel(package_dir: Path, out_dir: Path, name: str, version: str,
                     requires: list[str] | None = None, summary: str = "") -> Path:
    """Write a pure-Python wheel (``py3-none-any``) of one package folder.

    ``__pycache__`` folders and compiled files are left out. The wheel has the METADATA,
    WHEEL and RECORD files of the wheel spec (PEP 427), so pip and Blender install it.
    """
    files = shipped_files(package_dir)
    dist = f"{name}-{version}.dist-info"
    meta = ["Metadata-Version: 2.1", f"Name: {name}", f"Version: {version}"]
    if summary:
        meta.append(f"Summary: {summary}")
    meta += [f"Requires-Dist: {r}" for r in (requires or [])]
    generated = {
        f"{dist}/METADATA": ("\n".join(meta) + "\n").encode(),
        f"{dist}/WHEEL": b"Wheel-Version: 1.0\nGenerator: lipgen\nRoot-Is-Purelib: true\nTag: py3-none-any\n",
    }
    out = Path(out_dir) / f"{name}-{version}-py3-none-any.whl"
    records = io.StringIO()
    writer = csv.writer(records, lineterminator="\n")
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as zf:
        for p in files:
            arc = f"{Path(package_dir).name}/{p.relative_to(package_dir).as_posix()}"
            data = p.read_bytes()
            zf.writestr(zipfile.ZipInfo(arc, date_time=(2024, 1, 1, 0, 0, 0)), data,
                        compress_type=zipfile.ZIP_DEFLATED)
            writer.writerow([arc, _record_hash(data), len(data)])
        for arc, data in generated.items():
            zf.writestr(zipfile.ZipInfo(arc, date_time=(2024, 1, 1, 0, 0, 0)), data,
                        compress_type=zipfile.ZIP_DEFLATED)
            writer.writerow([arc, _record_hash(data), len(data)])
        writer.writerow([f"{dist}/RECORD", "", ""])
        zf.writestr(zipfile.ZipInfo(f"{dist}/RECORD", date_time=(2024, 1, 1, 0, 0, 0)),
                    records.getvalue().encode(), compress_type=zipfile.ZIP_DEFLATED)
    return out


def _pip_download(args: list[str], cache: Path, offline: bool) -> None:
    cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--only-binary=:all:",
           "--dest", str(cache), *args]
    if offline:
        cmd += ["--no-index", "--find-links", str(cache)]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    if run.returncode != 0:
        raise LookupError(run.stderr.strip().splitlines()[-1] if run.stderr.strip() else "pip failed")


def _wheel_matches(path: Path, dist: str, version: str) -> bool:
    parts = path.name[:-4].split("-")
    return parts[0].lower().replace("_", "-") == dist.lower() and parts[1] == version


def _platform_wheels(dist: str, version: str, platform: str, cache: Path, offline: bool) -> Path:
    """The cached (or now downloaded) wheel of ``dist==version`` for a Blender platform."""
    tags = PLATFORMS[platform]
    args = ["--python-version", PYTHON_VERSION, "--implementation", "cp", "--abi",
            "cp" + PYTHON_VERSION.replace(".", "")]
    for tag in tags:
        args += ["--platform", tag]
    before = set(cache.glob("*.whl"))
    _pip_download([*args, f"{dist}=={version}"], cache, offline)
    candidates = [p for p in cache.glob("*.whl") if _wheel_matches(p, dist, version)
                  and platform in _blender_platform_of(p.name)]
    if not candidates:
        new = sorted(p.name for p in set(cache.glob("*.whl")) - before)
        raise LookupError(f"pip gave no {dist} {version} wheel for {platform} (got {new})")
    return sorted(candidates)[-1]


def _blender_platform_of(wheel_name: str) -> set[str]:
    """Blender platforms a wheel file serves, from its platform tag(s)."""
    out: set[str] = set()
    for tag in wheel_name[:-4].split("-")[-1].split("."):
        if tag == "any":
            return set(PLATFORMS)
        if tag.startswith(("manylinux", "musllinux", "linux")):
            if tag.endswith("x86_64"):
                out.add("linux-x64")
            elif tag.endswith("aarch64"):
                out.add("linux-arm64")
        elif tag == "win_amd64":
            out.add("windows-x64")
        elif tag == "win_arm64":
            out.add("windows-arm64")
        elif tag.startswith("macosx"):
            if tag.endswith(("arm64", "universal2")):
                out.add("macos-arm64")
            if tag.endswith(("x86_64", "universal2")):
                out.add("macos-x64")
    return out


def _manifest_with(source_text: str, wheels: list[str], platforms: list[str]) -> str:
    """The manifest text with ``platforms`` and ``wheels`` set (top-level keys, before tables)."""
    keep: list[str] = []
    skipping = False
    for ln in source_text.splitlines():
        if not skipping and ln.split("=")[0].strip() in ("wheels", "platforms"):
            skipping = "]" not in ln  # a multi-line array runs to its closing bracket
            continue
        if skipping:
            skipping = "]" not in ln
            continue
        keep.append(ln)
    first_table = next((i for i, ln in enumerate(keep) if ln.lstrip().startswith("[")), len(keep))
    extra = ["platforms = [" + ", ".join(f'"{p}"' for p in platforms) + "]",
             "wheels = [", *[f'  "./wheels/{w}",' for w in wheels], "]", ""]
    text = "\n".join(keep[:first_table] + extra + keep[first_table:]) + "\n"
    tomllib.loads(text)  # never hand Blender a manifest we cannot read ourselves
    return text


def build_extension(out_dir: str | os.PathLike, platforms: list[str] | None = None,
                    cache: str | os.PathLike | None = None, offline: bool = False,
                    source: str | os.PathLike | None = None, blender: str | None = None,
                    check: bool = True) -> ExtensionBuild:
    """Build one extension zip per platform into ``out_dir`` and validate each.

    Parameters
    ----------
    out_dir : path
        Folder for the zips (created if missing). Existing zips of the same name are replaced.
    platforms : list of str, optional
        Blender platforms (keys of :data:`PLATFORMS`); all of them by default. A platform for
        which pip finds no wheel of a bundled package is skipped and reported.
    cache : path, optional
        Wheel cache folder (default ``~/.cache/lipgen/wheels``); downloads are reused.
    offline : bool
        Use only wheels already in the cache.
    source : path, optional
        The add-on folder (default: ``blender_addon/`` of this source tree).
    blender : str, optional
        A ``blender`` executable to build and validate with, instead of the pip bpy module's tool.
    check : bool
        Validate every zip with Blender's validator.
    """
    import tempfile

    import lipgen

    src = Path(source) if source else addon_source()
    if not (src / "blender_manifest.toml").is_file():
        raise FileNotFoundError(f"--source {src} is not a Blender add-on folder (no blender_manifest.toml "
                                "in it); pass the blender_addon/ folder of a lipgen checkout")
    chosen = list(platforms or PLATFORMS)
    unknown = [p for p in chosen if p not in PLATFORMS]
    if unknown:
        raise ValueError(f"unknown platform(s) {unknown}; choose from {sorted(PLATFORMS)}")
    cache = Path(cache) if cache else Path.home() / ".cache" / "lipgen" / "wheels"
    cache.mkdir(parents=True, exist_ok=True)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    versions = {d: metadata.version(d) for d in BUNDLED}
    skipped: dict[str, str] = {}
    per_platform: dict[str, list[Path]] = {}
    for platform in chosen:
        try:
            per_platform[platform] = [_platform_wheels(d, v, platform, cache, offline)
                                      for d, v in versions.items()]
        except LookupError as exc:
            skipped[platform] = str(exc)
            log.warning("skipping %s: %s", platform, exc)
    if not per_platform:
        raise LookupError(f"no platform could be built: {skipped}")
    with tempfile.TemporaryDirectory(prefix="lipgen-ext-") as tmp:
        stage = Path(tmp) / "lipgen"
        shutil.copytree(src, stage, ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.zip"))
        wheel_dir = stage / "wheels"
        wheel_dir.mkdir(exist_ok=True)
        requires = [f"{d}=={v}" for d, v in versions.items()]
        own = write_pure_wheel(Path(lipgen.__file__).parent, wheel_dir, "lipgen", lipgen.__version__,
                               requires, "Physically based 3D lip model (Basu 1997)")
        names = {own.name}
        for wheels in per_platform.values():
            for w in wheels:
                shutil.copy2(w, wheel_dir / w.name)
                names.add(w.name)
        manifest = stage / "blender_manifest.toml"
        manifest.write_text(_manifest_with(manifest.read_text(), sorted(names), sorted(per_platform)))
        cmd = [*_tool_command(blender), "build", "--source-dir", str(stage), "--output-dir", str(out),
               "--split-platforms"]
        run = subprocess.run(cmd, capture_output=True, text=True)  # no timeout: its time is the load's
        if run.returncode != 0:
            raise ValueError(f"Blender's extension builder failed: {(run.stdout + run.stderr).strip()}")
    meta = tomllib.loads((src / "blender_manifest.toml").read_text())
    zips = {}
    for platform in per_platform:
        z = out / f"{meta['id']}-{meta['version']}-{platform.replace('-', '_')}.zip"
        if not z.is_file():
            raise FileNotFoundError(f"the builder did not write {z}; it said: {run.stdout.strip()}")
        if check:
            validate(z, blender)
        zips[platform] = z
    return ExtensionBuild(zips, skipped, tuple(sorted(names)))
