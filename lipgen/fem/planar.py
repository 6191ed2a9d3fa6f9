"""The planar-mesh demonstration of the thesis's Fig 2-2.

A square sheet in the x-y plane, two opposite corners anchored, one out-of-plane force at the
centre node, under three stiffness layouts: (b) uniform E = 1; (c) a square ring of soft faces
around the centre; (d) soft faces inside the ring and much stiffer faces everywhere else. Panel
(a) is the sheet at rest. The thesis's claims, checked in the tests: the soft ring stretches more
than its stiffer neighbours, and the stiff surround deforms less than under uniform stiffness.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lipgen._io import atomic_path
from lipgen.fem.assembly import log as assembly_log
from lipgen.fem.physics import Physics
from lipgen.mesh.lipmesh import LipMesh

__all__ = ["PlanarDemo", "planar_sheet", "fig_2_2", "edge_stretch", "plot_fig_2_2"]

PLANAR_REGIONS: tuple[str, ...] = ("centre", "ring", "outer")


def planar_sheet(cells: int = 12, size: float = 12.0, ring: tuple[float, float] = (2.0, 3.0)) -> LipMesh:
    """A flat square sheet of ``cells x cells`` squares, each split in two along alternating
    diagonals (symmetric about both centre lines), in the x-y plane centred on the origin.

    Faces are tagged ``"centre"`` (centroid within ``ring[0]`` cells of the centre, Chebyshev
    distance), ``"ring"`` (up to ``ring[1]``) and ``"outer"``. Two opposite corners are anchored;
    the centre node is the only marker, ``"centre"``.
    """
    if cells < 2 or cells % 2:
        raise ValueError(f"cells must be an even number >= 2 (so a node sits at the centre), got {cells}")
    k = cells + 1
    x = np.linspace(-size / 2, size / 2, k)
    X, Y = np.meshgrid(x, x)
    V = np.c_[X.ravel(), Y.ravel(), np.zeros(k * k)]
    idx = np.arange(k * k).reshape(k, k)
    a, b = idx[:-1, :-1], idx[:-1, 1:]
    c, d = idx[1:, :-1], idx[1:, 1:]
    flip = (np.add.outer(np.arange(cells), np.arange(cells)) % 2).astype(bool)
    t1 = np.where(flip[..., None], np.stack([a, b, c], -1), np.stack([a, b, d], -1))
    t2 = np.where(flip[..., None], np.stack([b, d, c], -1), np.stack([a, d, c], -1))
    F = np.concatenate([t1.reshape(-1, 3), t2.reshape(-1, 3)])
    cheb = np.abs(V[F].mean(axis=1)[:, :2]).max(axis=1) / (size / cells)
    regions = np.where(cheb < ring[0], 0, np.where(cheb < ring[1], 1, 2))
    centre = int(idx[cells // 2, cells // 2])
    return LipMesh(V, F, regions, anchors=[int(idx[0, 0]), int(idx[-1, -1])], markers=[centre],
                   marker_names=("centre",), region_names=PLANAR_REGIONS, name="planar sheet")


def edge_stretch(mesh: LipMesh, U: np.ndarray) -> np.ndarray:
    """(m,) mean relative lengthening of each face's three edges under displacement ``U`` (n, 3)."""
    P, Q = mesh.vertices, mesh.vertices + U
    out = np.zeros(mesh.n_faces)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        a, b = mesh.faces[:, i], mesh.faces[:, j]
        out += np.linalg.norm(Q[b] - Q[a], axis=1) / np.linalg.norm(P[b] - P[a], axis=1) - 1.0
    return out / 3.0


@dataclass(frozen=True)
class PlanarDemo:
    """Fig 2-2's sheet and its three loaded cases.

    Attributes
    ----------
    mesh : LipMesh
    force : (n, 3) float
        The same out-of-plane force at the centre node in every case.
    stiffness : dict of str to (m,) float
        Per-face E of each case: ``"uniform"``, ``"soft ring"``, ``"soft centre"``.
    displacement : dict of str to (n, 3) float
        The displacement of each case, mm.
    """

    mesh: LipMesh
    force: np.ndarray
    stiffness: dict = field(default_factory=dict)
    displacement: dict = field(default_factory=dict)

    def stretch(self, case: str) -> np.ndarray:
        """(m,) per-face edge stretch of a case (see :func:`edge_stretch`)."""
        return edge_stretch(self.mesh, self.displacement[case])


def fig_2_2(cells: int = 12, size: float = 12.0, soft: float = 0.2, stiff: float = 5.0,
            lift: float = 0.25) -> PlanarDemo:
    """Compute the three deformations of Fig 2-2.

    Parameters
    ----------
    cells, size : int, float
        Sheet resolution (squares per side) and side length in mm.
    soft, stiff : float
        E of the soft ring / soft centre, and of the stiff surround in case (d); the default
        material is 1.
    lift : float
        The force is scaled so that the uniform sheet's centre rises ``lift * size``; the same
        force is then applied in all three cases (the model is linear).
    """
    mesh = planar_sheet(cells, size)
    code = {name: mesh.regions == i for i, name in enumerate(PLANAR_REGIONS)}
    ones = np.ones(mesh.n_faces)
    layouts = {
        "uniform": ones,
        "soft ring": np.where(code["ring"], soft, 1.0),
        "soft centre": np.where(code["centre"], soft, stiff),
    }
    centre = mesh.marker_index("centre")
    unit = np.zeros((mesh.n_nodes, 3))
    unit[centre, 2] = 1.0
    # Two corners are the thesis's own set-up: the line through them is held only by eq 2.13's
    # tilt penalty, which the grounding check would log as a warning for every case.
    quiet = assembly_log.level
    assembly_log.setLevel(logging.ERROR)
    try:
        physics = {name: Physics(mesh, E) for name, E in layouts.items()}
    finally:
        assembly_log.setLevel(quiet)
    scale = lift * size / physics["uniform"].displace(unit)[centre, 2]
    force = scale * unit
    shapes = {name: ph.displace(force) for name, ph in physics.items()}
    return PlanarDemo(mesh, force, layouts, shapes)


def plot_fig_2_2(demo: PlanarDemo, path: str | os.PathLike) -> Path:
    """Draw the four panels of Fig 2-2 (rest, uniform, soft ring, soft centre) to a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import colors
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    mesh = demo.mesh
    panels = [("(a) initial state", np.zeros_like(mesh.vertices), np.ones(mesh.n_faces))]
    titles = {"uniform": "(b) uniform stiffness", "soft ring": "(c) soft ring around the centre",
              "soft centre": "(d) soft centre, stiff surround"}
    panels += [(titles[k], demo.displacement[k], demo.stiffness[k]) for k in titles]
    norm = colors.LogNorm(vmin=min(E.min() for *_, E in panels), vmax=max(E.max() for *_, E in panels))
    zmax = max(float(U[:, 2].max()) for _, U, _ in panels)
    fig = plt.figure(figsize=(10, 9))
    for i, (title, U, E) in enumerate(panels):
        ax = fig.add_subplot(2, 2, i + 1, projection="3d")
        tri = (mesh.vertices + U)[mesh.faces]
        ax.add_collection3d(Poly3DCollection(tri, facecolors=plt.cm.coolwarm(norm(E)),
                                             edgecolors="k", linewidths=0.3))
        half = 0.5 * float(np.ptp(mesh.vertices[:, 0]))
        ax.set(xlim=(-half, half), ylim=(-half, half), zlim=(0, max(zmax, 1e-9)), title=title)
        ax.set_box_aspect((1, 1, 0.8))
        ax.view_init(elev=25, azim=-60)
        anchors = mesh.vertices[mesh.anchors]
        ax.scatter(*anchors.T, color="k", marker="s", s=30, depthshade=False)
    sm = plt.cm.ScalarMappable(norm=norm, cmap="coolwarm")
    fig.colorbar(sm, ax=fig.axes, shrink=0.5, label="relative stiffness E")
    fig.suptitle("Thesis Fig 2-2: one out-of-plane force at the centre, two corners anchored (squares)")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return path
