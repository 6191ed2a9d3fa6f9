"""The documentation: tutorials run as written, and the built site opens in a real browser.

A tutorial's ``python`` and ``sh`` blocks run in order in a fresh folder (``sh`` lines are
``lipgen`` commands, run through :func:`lipgen.cli.main`); blocks that start with ``# Blender``
run in a Blender session. ``text`` blocks are not run.
"""

from __future__ import annotations

import ast
import importlib.util
import re
import shlex
import shutil
import subprocess
from pathlib import Path

import pytest
from blender_session import BlenderSession, bpy_available

from lipgen import cli

ROOT = Path(__file__).resolve().parents[1]
TUTORIALS = ROOT / "docs" / "tutorials"
FENCE = re.compile(r"^```(\w+)[^\n]*\n(.*?)^```", re.S | re.M)
# What each tutorial needs beyond the core, as importable module names.
NEEDS = {"usd": ("pxr",), "validate": ("pyrender", "cv2"), "recording": ("pyrender", "cv2", "imageio_ffmpeg"),
         "blender": ("bpy",)}


def _blocks(page: Path) -> list[tuple[str, str]]:
    return [(lang, code) for lang, code in FENCE.findall(page.read_text()) if lang in ("python", "sh")]


def _pages() -> list[Path]:
    return sorted(TUTORIALS.glob("*.md"))


def _skip_unless_available(page: Path) -> None:
    missing = [m for m in NEEDS.get(page.stem, ()) if importlib.util.find_spec(m) is None]
    if missing:
        pytest.skip(f"{page.name} needs {', '.join(missing)} (make venv installs them)")


def test_every_tutorial_has_blocks_that_run():
    for page in _pages():
        assert _blocks(page), f"{page.name} has no python or sh block to test"


# The tutorials that run in `make test`; the others render and reconstruct frames or scan NRSfM's K
# (5-12 s each) and run in the slow set, while `make test` checks that every command of theirs parses.
QUICK = ("usd",)


def _params(quick: bool):
    # pages that render frames carry the render mark (left out of `make test-fast`)
    render = [pytest.mark.render]
    return [pytest.param(p, id=p.stem, marks=render if "pyrender" in NEEDS.get(p.stem, ()) else [])
            for p in _pages() if p.stem != "blender" and (p.stem in QUICK) == quick]


def _lipgen_lines(page: Path, code: str):
    """(line, its words) of each command of an sh block; every one must be a ``lipgen`` command."""
    for line in code.splitlines():
        args = shlex.split(line, comments=True)
        if not args:
            continue
        assert args[0] == "lipgen", f"{page.name}: sh blocks hold lipgen commands, got {line!r}"
        yield line, args


def _run_as_written(page: Path, tmp_path: Path, monkeypatch) -> None:
    _skip_unless_available(page)
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__tutorial__"}
    for i, (lang, code) in enumerate(_blocks(page)):
        if lang == "python":
            exec(compile(code, f"<{page.name} block {i + 1}>", "exec"), namespace)
            continue
        for line, args in _lipgen_lines(page, code):
            assert cli.main(args[1:]) == 0, f"{page.name}: `{line}` failed"


@pytest.mark.parametrize("page", _params(quick=True))
def test_tutorial_runs_as_written(page, tmp_path, monkeypatch):
    _run_as_written(page, tmp_path, monkeypatch)


@pytest.mark.slow(cover=("tests/test_docs.py::test_every_tutorial_command_parses_and_its_imports_resolve",
                         "tests/test_docs.py::test_tutorial_runs_as_written"))
@pytest.mark.parametrize("page", _params(quick=False))
def test_long_tutorial_runs_as_written(page, tmp_path, monkeypatch):
    _run_as_written(page, tmp_path, monkeypatch)


def test_every_tutorial_command_parses_and_its_imports_resolve(capsys):
    """What `make test` checks of the tutorials it does not run: each ``lipgen`` line parses with
    the command's own parser, each python block compiles, and its imports resolve (Blender's
    blocks aside: ``bpy`` is Blender's)."""
    for page in _pages():
        for i, (lang, code) in enumerate(_blocks(page)):
            where = f"{page.name} block {i + 1}"
            if lang == "python":
                tree = compile(code, f"<{where}>", "exec", flags=ast.PyCF_ONLY_AST)
                for node in tree.body:
                    if isinstance(node, (ast.Import, ast.ImportFrom)) and not code.startswith("# Blender"):
                        exec(compile(ast.Module([node], []), f"<{where}>", "exec"), {})
                continue
            for line, args in _lipgen_lines(page, code):
                try:
                    parsed = cli.build_parser(args[1]).parse_args(args[1:])
                except SystemExit:
                    err = capsys.readouterr().err
                    raise AssertionError(f"{where}: `{line}` does not parse: {err}") from None
                assert parsed.func, f"{where}: `{line}` names no command"


@pytest.mark.slow(cover="tests/test_docs.py::test_every_tutorial_command_parses_and_its_imports_resolve")
@pytest.mark.blender
@pytest.mark.skipif(not bpy_available(), reason="needs the pip bpy module")
def test_blender_tutorial_runs_in_blender(tmp_path):
    page = TUTORIALS / "blender.md"
    blocks = [code for lang, code in _blocks(page) if lang == "python"]
    assert blocks and all(code.startswith("# Blender") for code in blocks)
    _speech_wav(tmp_path / "speech.wav")  # the recording the Animate from Audio block reads
    session = BlenderSession()
    try:
        out = session.run("bpy_checks_docs:run_console_blocks", blocks, str(tmp_path))
    finally:
        session.close()
    assert "reach solved on LipGen Reach" in out
    assert "sound: [('speech', 1" in out
    assert (tmp_path / "lips_from_blender.usda").is_file()


def _speech_wav(path: Path) -> None:
    """The sentence of the tutorial's Animate from Audio block, spoken by eSpeak NG."""
    pytest.importorskip("pocketsphinx", reason="the Blender tutorial animates from audio: pip install "
                        "'lipgen[speech]'")
    from lipgen.speech import espeak
    from lipgen.speech.audio import write_wav

    if not espeak.available():
        pytest.skip("the Blender tutorial animates from a recording spoken by espeak-ng: apt-get install "
                    "espeak-ng (or `make espeak`)")
    write_wav(path, espeak.synthesize("The small pup gnawed a hole in the sock.")[0])


def test_site_opens_in_headless_chromium(tmp_path):
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        pytest.skip("Chromium is not installed (Debian: apt install chromium; `make docs` does it as root)")
    index = ROOT / "site" / "index.html"
    if not index.is_file():
        pytest.skip("no built site: run `make docs` first (CI builds it before the tests)")
    flags = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
             "--disable-background-networking", "--disable-component-update", "--disable-sync",
             f"--user-data-dir={tmp_path / 'profile'}", "--window-size=1280,1000"]
    shot = tmp_path / "index.png"
    subprocess.run([*flags, f"--screenshot={shot}", index.as_uri()], check=True, capture_output=True)
    dom = subprocess.run([*flags, "--dump-dom", index.as_uri()], check=True, capture_output=True,
                         text=True).stdout
    assert "figures/lips.png" in dom and "Animating lips in Blender" in dom
    import numpy as np
    from PIL import Image

    pixels = np.asarray(Image.open(shot).convert("L"), dtype=float)
    assert pixels.shape == (1000, 1280) and pixels.std() > 10, "the screenshot is blank"
