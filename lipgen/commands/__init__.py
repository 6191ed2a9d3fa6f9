"""Subcommands of the ``lipgen`` CLI, one module each (see :mod:`lipgen.cli`)."""
