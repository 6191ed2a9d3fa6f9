"""MkDocs hook: the API reference and the command-line reference, generated from the code.

Before the build, one page per stage package (every module in it, through mkdocstrings) and a
page of every command's ``--help`` are written into ``docs/reference/`` (git-ignored), and the
site's "Reference" section lists them. A new module or command appears without anyone editing
the docs, so the reference cannot drift from the code.
"""

from __future__ import annotations

import argparse
import pkgutil
from pathlib import Path

REFERENCE = Path(__file__).resolve().parents[1] / "reference"
# Stages in data-flow order (as in lipgen/__init__.py); anything else is appended after them.
ORDER = ("mesh", "fem", "modes", "usd", "rig", "subject", "speech", "dataset", "recon", "nrsfm",
         "evaluate", "campaign", "blender", "experiments", "bench")
SKIP = {"lipgen.commands", "lipgen.__main__", "lipgen._compat"}


def _modules(package: str) -> list[str]:
    import importlib

    pkg = importlib.import_module(package)
    names = [package]
    for info in pkgutil.walk_packages(pkg.__path__, prefix=package + "."):
        leaf = info.name.rsplit(".", 1)[-1]
        if not leaf.startswith("_") and not any(info.name.startswith(s) for s in SKIP):
            names.append(info.name)
    return names


def _stage_packages() -> list[str]:
    import lipgen

    found = [m.name for m in pkgutil.iter_modules(lipgen.__path__) if m.ispkg and m.name != "commands"]
    return [p for p in ORDER if p in found] + sorted(p for p in found if p not in ORDER)


def _write(path: Path, text: str) -> None:
    if not path.is_file() or path.read_text() != text:
        path.write_text(text)


def _package_page(stage: str) -> str:
    mods = _modules(f"lipgen.{stage}")
    lines = [f"# lipgen.{stage}", "", "Generated from the docstrings.", ""]
    for i, mod in enumerate(mods):
        # the package itself: its docstring only (its names are documented where they are defined)
        opts = "    options:\n      show_submodules: false" + ("\n      members: []" if i == 0 else "")
        lines += [f"::: {mod}", opts, ""]
    return "\n".join(lines)


def _root_page() -> str:
    import lipgen

    top = sorted(m.name for m in pkgutil.iter_modules(lipgen.__path__)
                 if not m.ispkg and not m.name.startswith("_") and m.name not in ("cli",))
    lines = ["# lipgen", "", "The package and its shared pieces (errors, tolerances).", "",
             "::: lipgen", "    options:\n      show_submodules: false", ""]
    for name in top:
        lines += [f"::: lipgen.{name}", ""]
    return "\n".join(lines)


def _cli_page() -> str:
    from lipgen.cli import build_parser

    parser = build_parser()
    lines = ["# Command line", "", "Every `lipgen` command's `--help`, generated from the parser.", "",
             "```text", parser.format_help().rstrip(), "```", ""]
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, p in sorted(sub.choices.items()):
        lines += [f"## lipgen {name}", "", "```text", p.format_help().rstrip(), "```", ""]
    return "\n".join(lines)


def on_config(config, **kwargs):
    import os

    os.environ.setdefault("COLUMNS", "100")  # argparse wraps the help to this width
    REFERENCE.mkdir(exist_ok=True)
    pages = [{"Command line": "reference/cli.md"}, {"lipgen": "reference/lipgen.md"}]
    _write(REFERENCE / "cli.md", _cli_page())
    _write(REFERENCE / "lipgen.md", _root_page())
    for stage in _stage_packages():
        _write(REFERENCE / f"{stage}.md", _package_page(stage))
        pages.append({stage: f"reference/{stage}.md"})
    for item in config["nav"]:
        if isinstance(item, dict) and "Reference" in item:
            item["Reference"] = [{"Map": "API.md"}, *pages]
    return config
