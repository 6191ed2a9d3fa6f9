"""Choosing the renderer of the rig: pyrender (OpenGL, the default) or Blender Cycles (photoreal).

Both draw the same :class:`~lipgen.rig.scene.Scene` through the same view cameras of a
:class:`~lipgen.rig.camera.MirrorRig`, so the truth is the same whichever is chosen; they differ
in how light is computed (rasterised local shading against path tracing with subsurface
scattering) and in cost. Each is imported only when opened.
"""

from __future__ import annotations

import os

from lipgen.rig.camera import MirrorRig
from lipgen.rig.conditions import ImageConditions

__all__ = ["RENDERERS", "check_renderer", "open_renderer"]

RENDERERS: tuple[str, ...] = ("pyrender", "cycles")
"""The renderers by name: ``pyrender`` (:class:`~lipgen.rig.render.RigRenderer`) and ``cycles``
(:class:`~lipgen.rig.cycles.CyclesRenderer`)."""


def _check_name(name) -> str:
    if name not in RENDERERS:
        raise ValueError(f"unknown renderer {name!r}; choose one of {RENDERERS}")
    return name


def check_renderer(name: str) -> None:
    """Raise now, before any work, if renderer ``name`` is unknown or (Cycles) cannot be imported.

    pyrender is not opened here: a process that only prepares a dataset needs no OpenGL, and
    :func:`open_renderer` says what is missing when it is.

    Raises
    ------
    ValueError
        ``name`` is not in :data:`RENDERERS`.
    MissingDependencyError
        ``cycles`` without the pip ``bpy``; the message gives the ``pip install`` line.
    """
    if _check_name(name) == "cycles":
        from lipgen.rig.cycles import import_bpy

        import_bpy()


def open_renderer(name: str, rig: MirrorRig, conditions: ImageConditions | None = None,
                  samples: int = 16, seed: int = 0):
    """A renderer of ``rig`` under the mirror and light settings of ``conditions``.

    Parameters
    ----------
    name : {"pyrender", "cycles"}
    rig : MirrorRig
    conditions : ImageConditions, optional
        Its ``mirror_reflectance`` and ``shadows`` are used (default: the ideal camera's).
    samples : int
        Cycles' path-tracing samples per pixel (pyrender ignores it).
    seed : int
        Cycles' sampling seed (pyrender ignores it).

    Returns
    -------
    RigRenderer or CyclesRenderer
        With ``render(scene)``, ``render_views(scene)`` and ``close()``. Cycles uses as many CPU
        threads as ``OMP_NUM_THREADS`` says (one in ``generate``'s pool workers), else all cores.
    """
    conditions = ImageConditions() if conditions is None else conditions
    if not isinstance(conditions, ImageConditions):
        raise TypeError(f"conditions must be ImageConditions, got {type(conditions).__name__}")
    if _check_name(name) == "cycles":
        from lipgen.rig.cycles import CyclesRenderer

        threads = os.environ.get("OMP_NUM_THREADS", "")
        return CyclesRenderer(rig, conditions.mirror_reflectance, shadows=conditions.shadows,
                              samples=samples, seed=seed, threads=int(threads) if threads.isdigit() else 0)
    from lipgen.rig.render import RigRenderer

    return RigRenderer(rig, conditions.mirror_reflectance, shadows=conditions.shadows)
