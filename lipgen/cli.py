"""The ``lipgen`` command line.

Each subcommand lives in a module of :mod:`lipgen.commands` that defines
``add_parser(subparsers)``; the parser it adds sets ``func(args) -> int``. Register new
commands in ``COMMANDS`` (name -> module, one-line help).

Commands are imported lazily: ``lipgen --help`` lists them from ``COMMANDS`` without importing
any, and ``lipgen NAME ...`` imports only NAME's module, so start-up does not pay for scipy,
the physics or pyrender unless the command needs them.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

from lipgen import __version__

__all__ = ["COMMANDS", "main", "build_parser"]

COMMANDS: dict[str, tuple[str, str]] = {
    "bench": ("lipgen.commands.bench", "run the benchmarks and write JSON (machine, versions, figures)"),
    "nrsfm": ("lipgen.commands.nrsfm", "non-rigid structure from motion: 2D tracks -> 3D shapes"),
    "experiment": ("lipgen.commands.experiment",
                   "run an experiment of the thesis on synthetic truth and write its report"),
    "demo": ("lipgen.commands.demo",
             "the whole loop on the default subject: physics pictures, dataset, reconstruction, "
             "modes, evaluation against the truth, USD; report in OUT/demo/report/"),
    "mesh": ("lipgen.commands.mesh",
             "write the default procedural lips (OBJ/PLY/NPZ + annotations) and draw them"),
    "export-usd": ("lipgen.commands.export_usd",
                   "write lip animation to USD: learned modes as UsdSkel blend shapes and/or baked points"),
    "blender-extension": ("lipgen.commands.blender_extension",
                          "build the Blender extension zip(s): the add-on plus lipgen and its wheels"),
    "generate": ("lipgen.commands.generate", "render a synthetic camera-mirror dataset with ground truth"),
    "show": ("lipgen.commands.show", "save an annotated picture of a dataset frame"),
    "recording": ("lipgen.commands.recording",
                  "bring your own camera-mirror recording into the dataset layout"),
    "reconstruct": ("lipgen.commands.reconstruct",
                    "reconstruct displacement fields from a dataset's raw frames"),
    "train": ("lipgen.commands.train", "learn displacement modes (ModeModel) from a reconstruction"),
    "evaluate": ("lipgen.commands.evaluate",
                 "score reconstruction and model against the dataset's ground truth"),
    "lipsync": ("lipgen.commands.lipsync",
                "animate the lips from speech audio and/or text (USD with audio, npz, csv)"),
    "campaign": ("lipgen.commands.campaign",
                 "run many datasets through the stages on Ray; one aggregated report"),
}
"""Command name -> (module defining ``add_parser``, one-line help shown by ``lipgen --help``)."""

COMMAND_MODULES: tuple[str, ...] = tuple(module for module, _ in COMMANDS.values())

_DESCRIPTION = """\
lipgen: a physically based 3D lip model (Basu 1997).

Thin-shell finite-element physics, learned modes and LLSE reconstruction, USD export, a
Blender add-on, and a synthetic camera-mirror dataset generator for testing 3D lip
reconstruction against ground truth. Run `lipgen COMMAND --help` for each command.

examples:
  lipgen demo --out renders            the whole loop, with a report
  lipgen nrsfm --help                  one command's options
"""

_ALL = object()


def _chosen_command(argv: list[str]) -> str | None:
    """The first argument that names a command (the options before it take no values)."""
    for arg in argv:
        if arg == "--":
            return None
        if not arg.startswith("-"):
            return arg if arg in COMMANDS else None
    return None


def build_parser(command: str | None | object = _ALL) -> argparse.ArgumentParser:
    """The argument parser; only ``command``'s module is imported (every module by default).

    Other commands get a placeholder subparser with their help line, enough for
    ``lipgen --help`` and for argparse's "invalid choice" message.
    """
    parser = argparse.ArgumentParser(
        prog="lipgen", description=_DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"lipgen {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module, help_line) in COMMANDS.items():
        if command is _ALL or name == command:
            importlib.import_module(module).add_parser(sub)
        else:
            sub.add_parser(name, help=help_line, add_help=False)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``lipgen`` with ``argv`` (default: the command line); returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(_chosen_command(argv))
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
    except MemoryError as exc:  # a size the machine cannot hold: say which, not a traceback
        if args.verbose >= 2:
            raise
        sys.stderr.write(f"lipgen {args.command}: error: out of memory ({exc or 'no detail'}); give smaller "
                         "sizes (fewer frames, a smaller image, a coarser mesh)\n")
        return 1


if __name__ == "__main__":
    raise SystemExit(main())
