"""The ``lipgen`` command line.

Each subcommand lives in a module of :mod:`lipgen.commands` that defines
``add_parser(subparsers)``; the parser it adds sets ``func(args) -> int``. Register new
modules in ``COMMAND_MODULES``.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

from lipgen import __version__

__all__ = ["main", "build_parser"]

COMMAND_MODULES: tuple[str, ...] = (
    "lipgen.commands.bench",
    "lipgen.commands.nrsfm",
    "lipgen.commands.experiment",
    "lipgen.commands.demo",
    "lipgen.commands.mesh",
    "lipgen.commands.export_usd",
    "lipgen.commands.blender_extension",
    "lipgen.commands.generate",
    "lipgen.commands.show",
    "lipgen.commands.reconstruct",
    "lipgen.commands.train",
    "lipgen.commands.evaluate",
    "lipgen.commands.lipsync",
)

_DESCRIPTION = """\
lipgen: a physically based 3D lip model (Basu 1997).

Thin-shell finite-element physics, learned modes and LLSE reconstruction, USD export, a
Blender add-on, and a synthetic camera-mirror dataset generator for testing 3D lip
reconstruction against ground truth. Run `lipgen COMMAND --help` for each command.
"""


def build_parser() -> argparse.ArgumentParser:
    """The ``lipgen`` argument parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="lipgen", description=_DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"lipgen {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``lipgen`` with ``argv`` (default: the command line); returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    level = logging.WARNING - 10 * min(args.verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except (ValueError, TypeError, OSError, ImportError) as exc:
        # Domain and input errors end the command with their message, not a traceback.
        if args.verbose >= 2:
            raise
        sys.stderr.write(f"lipgen {args.command}: error: {exc}\n")
        return 1


if __name__ == "__main__":
    raise SystemExit(main())
