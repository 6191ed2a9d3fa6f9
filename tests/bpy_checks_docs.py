"""Run the Blender tutorial's console blocks inside a Blender worker (see blender_session.py)."""

from __future__ import annotations

import contextlib
import io
import os

from bpy_checks_addon import fresh


def run_console_blocks(blocks: list[str], cwd: str) -> str:
    """Execute ``blocks`` in order in one namespace, as typed into Blender's Python console."""
    fresh()
    os.chdir(cwd)
    namespace: dict = {"__name__": "__console__"}
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        for i, code in enumerate(blocks):
            exec(compile(code, f"<tutorials/blender.md block {i + 1}>", "exec"), namespace)
    return out.getvalue()
