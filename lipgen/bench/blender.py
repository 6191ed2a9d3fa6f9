"""Benchmark suite ``blender``: the add-on's playback and live force preview inside Blender.

- **Playback**: a 10-mode rig (modes built from the physics, every slider keyframed) played
  frame by frame: ``frame_set`` + depsgraph evaluation + ``to_mesh`` + reading the vertices, at
  resolution 0 (201 vertices) and resolution 3 (11,352). Baseline, in the same process: the same
  evaluation of the same mesh without shape keys.
- **Force preview**: one update of the live preview at resolution 3 (the magnitude slider's
  update callback: a weighted sum of the stored unit responses written into a shape key), and
  the update plus the depsgraph evaluation that shows it. Target: under 30 ms. Baseline: writing
  the same shape key from a ready array.

bpy is imported only in a child process (``python -m blender_addon._bench_worker`` from the
source tree), never in the benchmarking process.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from lipgen._optional import require

NAME = "blender"


def run(quick: bool = False) -> dict:
    from lipgen.blender.packaging import addon_source

    source = addon_source()
    if importlib.util.find_spec("bpy") is None:
        require("bpy", "the blender benchmark")  # raises with the install hint
    with tempfile.TemporaryDirectory(prefix="lipgen-bench-blender-") as tmp:
        out = Path(tmp) / "blender.json"
        cmd = [sys.executable, "-m", "blender_addon._bench_worker", str(out)] + (["--quick"] if quick else [])
        proc = subprocess.run(cmd, cwd=source.parent, capture_output=True, text=True, timeout=3600)
        if proc.returncode != 0:
            raise RuntimeError(f"the Blender worker failed: {proc.stderr.strip()[-2000:]}")
        return json.loads(out.read_text())
