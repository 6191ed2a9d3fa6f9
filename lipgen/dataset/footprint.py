"""The memory a dataset's truth motion needs, checked before the truth physics runs.

The motion is held whole: (F, n, 3) float64 vertices for F frames of an n-vertex subject mesh, and
the linear truth's sum of responses, jaw and contact terms makes about a dozen temporaries of that
shape at its peak. Measured with ``tracemalloc`` on :func:`lipgen.dataset.simulation.simulate_motion`
(300 frames; preset ``easy`` and ``default``; subject resolution 1 and 2): 250-330 bytes per vertex
and frame at the peak; the nonlinear layer (preset ``hard``) peaks at about 70 MB, nearly all of it
fixed (6 and 12 frames). Each rendering worker receives its own copy of the vertices.
So ``--frames 1000 --subject-resolution 4`` (44,976 vertices) needs about 15 GB: refused on a
machine without it, before minutes of physics, instead of being killed by the kernel after them.
"""

from __future__ import annotations

from lipgen.errors import DatasetError

__all__ = ["PEAK_BYTES_PER_VERTEX_FRAME", "motion_peak_bytes", "available_bytes", "check_motion_memory"]

PEAK_BYTES_PER_VERTEX_FRAME = 340
"""Peak bytes of the truth motion per vertex and frame (the largest measured, 332, rounded up)."""
FIXED_BYTES = 100 << 20
"""What the physics holds whatever the length (the nonlinear layer's model: about 70 MB)."""


def motion_peak_bytes(frames: int, n_vertices: int, workers: int = 1) -> int:
    """Peak bytes of the truth motion of ``frames`` frames on ``n_vertices`` vertices, with the
    copy each of ``workers`` rendering processes holds."""
    return FIXED_BYTES + frames * n_vertices * (PEAK_BYTES_PER_VERTEX_FRAME + 24 * workers)


def available_bytes() -> int | None:
    """The memory the kernel says can be had without swapping (``MemAvailable``), or None off Linux."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def check_motion_memory(frames: int, subject_resolution: int, workers: int = 1,
                        available: int | None = None) -> int:
    """Refuse (``DatasetError``, naming the need, what is free and the fix) a motion the machine cannot
    hold; returns the estimate in bytes. ``available`` defaults to :func:`available_bytes` (unknown:
    no check)."""
    from lipgen.mesh.procedural import lip_mesh

    n = lip_mesh(int(subject_resolution)).n_nodes
    need = motion_peak_bytes(frames, n, workers)
    free = available_bytes() if available is None else available
    if free is not None and need > free:
        fit = max(1, int((free - FIXED_BYTES) // (n * (PEAK_BYTES_PER_VERTEX_FRAME + 24 * workers))))
        raise DatasetError(
            f"--frames {frames} at subject resolution {subject_resolution} ({n} vertices) needs about "
            f"{need / 2**30:.1f} GB for the truth motion, but {free / 2**30:.1f} GB is free; generate at "
            f"most about {fit} frames per dataset (several datasets with other seeds), or a lower "
            "--subject-resolution (nothing was written)")
    return need
