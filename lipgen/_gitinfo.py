"""Which code ran: the git commit of the source tree (benchmarks and experiment reports record it)."""

from __future__ import annotations

import subprocess
from pathlib import Path

__all__ = ["git_revision", "code_version"]

_TREE = Path(__file__).resolve().parents[1]
_RUN = {"capture_output": True, "text": True, "timeout": 10, "check": True}


def git_revision() -> str | None:
    """The commit of the source tree (HEAD); None outside a git checkout or without git."""
    try:
        return subprocess.run(["git", "-C", str(_TREE), "rev-parse", "HEAD"], **_RUN).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None


def code_version() -> dict:
    """lipgen's version and, in a git checkout, the commit and whether the tree had changes
    (tracked files only); the git entries are None without git."""
    from lipgen import __version__

    out = {"lipgen": __version__, "git_commit": git_revision(), "git_dirty": None}
    if out["git_commit"] is not None:
        try:
            git = ["git", "-C", str(_TREE), "status", "--porcelain", "--untracked-files=no"]
            out["git_dirty"] = bool(subprocess.run(git, **_RUN).stdout.strip())
        except (OSError, subprocess.SubprocessError):
            pass
    return out
