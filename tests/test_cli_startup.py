"""The CLI imports commands lazily: `lipgen --help` pays for no heavy module (issue 22)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from lipgen import cli

_HEAVY = ("scipy.optimize", "scipy.sparse", "lipgen.fem", "lipgen.nrsfm", "pyrender", "matplotlib")

_PROBE = """
import json, sys
from lipgen.cli import main
try:
    main({argv!r})
except SystemExit:
    pass
print(json.dumps(sorted(sys.modules)))
"""


def _modules_after(argv: list[str]) -> set[str]:
    out = subprocess.run([sys.executable, "-c", _PROBE.format(argv=argv)], capture_output=True, text=True,
                         check=True)
    return set(json.loads(out.stdout.splitlines()[-1]))


@pytest.mark.parametrize("argv", [["--help"], ["nrsfm", "--help"], []])
def test_help_imports_no_heavy_module(argv):
    loaded = _modules_after(argv)
    assert not [m for m in _HEAVY if m in loaded], sorted(m for m in loaded if m.startswith(_HEAVY))
    if argv in (["--help"], []):
        assert "numpy" not in loaded  # listing the commands needs nothing numeric


def test_chosen_command_only_is_imported():
    loaded = _modules_after(["mesh", "--help"])
    assert "lipgen.commands.mesh" in loaded
    others = [m for _, (m, _h) in cli.COMMANDS.items() if m != "lipgen.commands.mesh"]
    assert not [m for m in others if m in loaded]


def test_table_matches_the_modules():
    """The help lines in COMMANDS are the ones each module registers, and each name exists."""
    parser = cli.build_parser()  # imports every command module
    sub = next(a for a in parser._actions if a.dest == "command")
    helps = {c.dest: c.help for c in sub._choices_actions}
    assert set(sub.choices) == set(cli.COMMANDS)
    for name, (_module, help_line) in cli.COMMANDS.items():
        assert helps[name] == help_line, name


def test_nrsfm_choices_match_the_methods():
    from lipgen.commands.nrsfm import DEFAULT_METHOD, METHOD_NAMES
    from lipgen.nrsfm import DEFAULT_METHOD as default
    from lipgen.nrsfm import METHODS

    assert tuple(sorted(METHODS)) == METHOD_NAMES and DEFAULT_METHOD == default


def test_chosen_command_parsing():
    assert cli._chosen_command(["-v", "nrsfm", "x.npz"]) == "nrsfm"
    assert cli._chosen_command(["--help"]) is None
    assert cli._chosen_command(["bogus"]) is None


def test_unknown_command_is_an_argparse_error(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["bogus"])
    assert exc.value.code == 2
    assert "invalid choice: 'bogus'" in capsys.readouterr().err


def _parsers(parser, path=()):
    """Every (sub)parser under ``parser``, with its command path."""
    yield path, parser
    for action in parser._actions:
        if isinstance(action.choices, dict):
            for name, sub in action.choices.items():
                yield from _parsers(sub, (*path, name))


def test_every_commands_help_formats():
    # argparse %-formats each help string: a bare "%" in one (as "60 %" did) breaks that
    # command's --help with a TypeError, which no other test reaches
    parsers = list(_parsers(cli.build_parser()))
    assert len(parsers) > len(cli.COMMANDS)
    for path, parser in parsers:
        text = parser.format_help()
        assert text.startswith("usage:"), path
