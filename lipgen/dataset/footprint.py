"""The memory a dataset's truth motion needs, checked before the truth physics runs.

The motion is held whole, (F, n, 3) float64 vertices for F frames of an n-vertex subject mesh, with
temporaries of that shape at its peak; and the physics holds a fixed part that grows faster than n
(its factorisations). Measured as the growth of the resident set (``ru_maxrss``) over
:func:`lipgen.dataset.simulation.simulate_motion`, presets ``easy`` and ``default`` (linear truth), at
10 and 110 frames (60 at resolution 3), and ``default`` at 20, 220 and 420 frames in fresh processes:
165-240 bytes per vertex and frame; fixed about 19, 58 and
300 MB at subject resolution 1, 2 and 3, and 2.1 GB at 4 (10 frames). The nonlinear layer (preset
``hard``) holds about 162 MB at resolution 1 and 440 MB at 2 (3-6 frames); at 3 and 4 it was not
measured and is taken as 8 times the linear truth's (its ratio at 1 and 2). The rendering workers
start after the physics, each with its own copy of the vertices (their processes' own cost, the
interpreter and the renderer, is not counted). So ``--frames 1000 --subject-resolution 4`` needs
about 13 GB: refused on a machine without it before minutes of physics, instead of being killed by
the kernel after them. ``LIPGEN_MEMORY_CHECK=off`` skips the check.
"""

from __future__ import annotations

import os

from lipgen.errors import DatasetError

__all__ = ["BYTES_PER_VERTEX_FRAME", "FIXED_MB", "motion_peak_bytes", "available_bytes",
           "check_motion_memory", "MEMORY_CHECK_ENV"]

BYTES_PER_VERTEX_FRAME = 260
"""The truth motion's peak bytes per vertex and frame (the largest measured, 240, with a margin)."""
FIXED_MB = {"linear": {1: 20, 2: 60, 3: 310, 4: 2150}, "layer": {1: 170, 2: 450, 3: 2500, 4: 17000}}
"""What the physics holds whatever the length, MB, by truth physics and subject resolution (see above)."""
MEMORY_CHECK_ENV = "LIPGEN_MEMORY_CHECK"
"""Set to ``off`` to skip :func:`check_motion_memory` (e.g. where swap makes up the difference)."""


def motion_peak_bytes(frames: int, n_vertices: int, subject_resolution: int = 1,
                      truth_physics: str = "linear", workers: int = 1) -> int:
    """Peak bytes of the truth motion of ``frames`` frames on ``n_vertices`` vertices, or of the
    rendering that follows it (the motion held, and a copy per worker when there are several)."""
    table = FIXED_MB["layer" if truth_physics == "layer" else "linear"]
    fixed = table[min(max(int(subject_resolution), 1), max(table))] << 20
    held = 24 * frames * n_vertices
    physics = fixed + BYTES_PER_VERTEX_FRAME * frames * n_vertices
    return int(max(physics, held * (1 + (workers if workers > 1 else 0))))


def available_bytes() -> int | None:
    """Memory that can be had without swapping: the kernel's ``MemAvailable``, or less where a cgroup
    (a container, a CI runner) limits this process; None when neither is known."""
    free = None
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    free = int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        free = None
    for limit, used in (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
                        ("/sys/fs/cgroup/memory/memory.limit_in_bytes",
                         "/sys/fs/cgroup/memory/memory.usage_in_bytes")):
        try:
            with open(limit) as a, open(used) as b:
                text = a.read().strip()
                if text == "max" or int(text) >= 1 << 60:
                    continue
                room = int(text) - int(b.read().strip())
        except (OSError, ValueError):
            continue
        free = room if free is None else min(free, room)
    return free


def check_motion_memory(frames: int, subject_resolution: int, truth_physics: str = "linear", workers: int = 1,
                        available: int | None = None) -> int:
    """Refuse (``DatasetError``, naming the need, what is free and the fix) a motion the machine cannot
    hold; returns the estimate in bytes. ``available`` defaults to :func:`available_bytes` (unknown:
    no check); :data:`MEMORY_CHECK_ENV` ``=off`` skips the refusal."""
    from lipgen.mesh.procedural import lip_mesh

    n = lip_mesh(int(subject_resolution)).n_nodes
    need = motion_peak_bytes(frames, n, subject_resolution, truth_physics, workers)
    free = available_bytes() if available is None else available
    if free is None or need <= free or os.environ.get(MEMORY_CHECK_ENV, "").lower() == "off":
        return need
    base = motion_peak_bytes(0, n, subject_resolution, truth_physics)
    fit = int((free - base) // (n * BYTES_PER_VERTEX_FRAME)) if free > base else 0
    advice = (f"at most about {fit} frames fit (make several datasets with other seeds)" if fit >= 1 else
              "no length fits at this subject resolution")
    raise DatasetError(
        f"{frames} frames at subject resolution {subject_resolution} ({n} vertices, {truth_physics} truth) "
        f"need "
        f"about {need / 2**30:.1f} GB for the truth motion, but {free / 2**30:.1f} GB is free: {advice}; or "
        f"lower the subject resolution. Nothing was written ({MEMORY_CHECK_ENV}=off skips this check)")
