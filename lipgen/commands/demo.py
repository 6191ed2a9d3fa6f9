"""``lipgen demo``: the default lips through the pipeline, with pictures under ``--out``.

The demo is a plain sequence of steps, each a small function that returns what it wrote, so
that later stages (motion, rendering, reconstruction) can be appended as further steps.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

# Named forces: (marker names, direction) pairs, each pulling the markers' nodes one way.
NAMED_FORCES: dict[str, tuple[tuple[tuple[str, ...], tuple[float, float, float]], ...]] = {
    "lower lip down": ((("lower_mid", "lower_left", "lower_right"), (0.0, -1.0, 0.0)),),
    "upper lip up": ((("upper_mid", "upper_left", "upper_right"), (0.0, 1.0, 0.0)),),
    "corners out": ((("corner_left",), (1.0, 0.0, 0.0)), (("corner_right",), (-1.0, 0.0, 0.0))),
    "protrude": ((("upper_mid", "lower_mid", "upper_left", "upper_right", "lower_left",
                   "lower_right"), (0.0, 0.0, 1.0)),),
}


def named_force(mesh, name: str, peak_mm: float, physics) -> np.ndarray:
    """(n, 3) force for one of :data:`NAMED_FORCES`, scaled so the largest displacement is
    ``peak_mm`` (the model is linear, so the shape does not depend on the scale)."""
    if name not in NAMED_FORCES:
        raise ValueError(f"unknown named force {name!r}; known: {sorted(NAMED_FORCES)}")
    F = np.zeros((mesh.n_nodes, 3))
    for markers, direction in NAMED_FORCES[name]:
        for marker in markers:
            F[mesh.marker_index(marker)] += direction
    peak = np.linalg.norm(physics.displace(F), axis=1).max()
    return F * (peak_mm / peak)


def step_physics(resolution: int):
    """Build the default lips and their physics."""
    import lipgen

    mesh = lipgen.lip_mesh(resolution)
    t0 = time.perf_counter()
    physics = lipgen.Physics(mesh)
    log.info("physics: %d nodes, %d faces, solver %s, %.2f s", mesh.n_nodes, mesh.n_faces,
             physics.solver, time.perf_counter() - t0)
    return mesh, physics


def step_named_forces(mesh, physics, out: Path, peak_mm: float = 4.0) -> Path:
    """Deform the lips under each named force; one row per force (front and profile views)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    from .._io import atomic_path
    from ..plot_mesh import draw_mesh

    names = list(NAMED_FORCES)
    forces = np.stack([named_force(mesh, n, peak_mm, physics) for n in names])
    U = physics.displace(forces)  # one batched solve for all of them
    fig = Figure(figsize=(10, 4.0 * len(names)), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(names), 2, squeeze=False)
    for row, (name, u) in enumerate(zip(names, U, strict=True)):
        mag = np.linalg.norm(u, axis=1)
        for ax, view in zip(axes[row], ("front", "profile"), strict=True):
            draw_mesh(ax, mesh, view, vertices=mesh.vertices + u, values=mag, vmin=0.0, vmax=peak_mm,
                      cmap="magma", nose=False)
            ax.set_title(f"{name} ({view})", fontsize=10)
    fig.colorbar(ScalarMappable(Normalize(0.0, peak_mm), "magma"), ax=axes.ravel().tolist(),
                 shrink=0.5, label="displacement (mm)")
    fig.suptitle(f"Default lips ({mesh.n_nodes} nodes) under named forces; anchors marked x",
                 fontsize=11)
    path = out / "physics_forces.png"
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    return path


def step_rest_state(mesh, physics, out: Path, close_mm: float = 1.5):
    """Thesis §2.4 / Fig 4-1: reach marker goals (the lips closing by ``close_mm`` each at the
    midline, the other markers held where they are) and re-linearise there."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from .. import dofs
    from .._io import atomic_path
    from ..plot_mesh import draw_mesh

    goals = np.zeros((len(mesh.markers), 3))
    for name, sign in (("upper_mid", -1.0), ("lower_mid", 1.0)):
        goals[mesh.marker_names.index(name), 1] = sign * close_mm
    d = dofs(mesh.markers, "xyz")
    rest = physics.to_rest_state(d, goals.ravel())
    U = rest.mesh.vertices - mesh.vertices
    fig = Figure(figsize=(10, 8), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, 2)
    for row, (label, V) in enumerate((("initial", mesh.vertices), ("rest state", rest.mesh.vertices))):
        for ax, view in zip(axes[row], ("front", "profile"), strict=True):
            draw_mesh(ax, mesh, view, vertices=V, values=np.linalg.norm(U, axis=1) if row else None,
                      cmap="magma", vmin=0.0, vmax=close_mm, nose=False)
            ax.set_title(f"{label} ({view})", fontsize=10)
    fig.suptitle("Deformation to the rest state (thesis Fig 4-1): marker goals reached with the "
                 "least-norm force (eq 4.3), physics re-linearised there", fontsize=10)
    path = out / "rest_state.png"
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    return rest, path


def step_fig_2_2(out: Path) -> Path:
    """The planar demonstration of the thesis's Fig 2-2."""
    from ..fem.planar import fig_2_2, plot_fig_2_2

    return plot_fig_2_2(fig_2_2(), out / "fig_2_2.png")


def run(out_dir: str | Path, resolution: int = 0) -> list[Path]:
    """Run every demo step; returns the files written."""
    out = Path(out_dir) / "demo"
    out.mkdir(parents=True, exist_ok=True)
    written = []
    mesh, physics = step_physics(resolution)
    written.append(step_named_forces(mesh, physics, out))
    _rest, path = step_rest_state(mesh, physics, out)
    written.append(path)
    written.append(step_fig_2_2(out))
    return written


def add_parser(sub) -> None:
    p = sub.add_parser(
        "demo",
        help="build the default lips, deform them, and save pictures",
        description="Build the default procedural lips and their thin-shell physics, deform them "
        "under a few named forces (lower lip down, upper lip up, corners out, protrude), deform "
        "them to a rest state from marker goals (thesis Fig 4-1) and draw the thesis's Fig 2-2 "
        "planar demonstration. Pictures go to OUT/demo/.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--out", default="renders", help="output folder (pictures go to OUT/demo/)")
    p.add_argument("--resolution", type=int, default=0, choices=range(0, 5),
                   help="lip mesh resolution (0: ~200 nodes; each step ~4x)")
    p.set_defaults(func=_run)


def _run(args) -> int:
    for path in run(args.out, args.resolution):
        sys.stdout.write(f"wrote {path}\n")
    return 0
