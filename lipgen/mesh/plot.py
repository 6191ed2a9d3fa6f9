"""Pictures of lip meshes (matplotlib, Agg): regions or per-vertex values, markers, anchors, nose.

The surface is drawn as flat-shaded polygons sorted back to front (painter's algorithm) in an
orthographic view, which is fast enough for resolution 2 (5,568 faces) and exact for the convex-ish
views used here. Pass ``vertices`` to draw a deformed mesh and ``values`` to colour it by a
per-vertex quantity (e.g. displacement magnitude).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from lipgen._io import atomic_savefig
from lipgen._validate import as_float_array
from lipgen.mesh.lipmesh import LipMesh

__all__ = ["REGION_COLORS", "VIEWS", "draw_mesh", "plot_mesh", "render_default_lips"]

REGION_COLORS = {"lip": "#c8505a", "ridge": "#7a1f3d", "strip": "#e8b04a", "skin": "#e6c3a5"}
"""Base colour of each default region (other region names get grey)."""

VIEWS = {"front": (0.0, 0.0), "profile": (-90.0, 0.0), "oblique": (-35.0, 15.0), "below": (0.0, -40.0)}
"""Named views as (azimuth, elevation) in degrees: azimuth 0 looks at the face from the front
(+z towards the camera, +x to the right), -90 from the subject's right side (+z to the right)."""


def _camera(view) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit (right, up, towards-camera) axes for a view name or (azimuth, elevation) in degrees."""
    if isinstance(view, str):
        if view not in VIEWS:
            raise ValueError(f"unknown view {view!r}; use one of {sorted(VIEWS)} or (azimuth, elevation)")
        view = VIEWS[view]
    az, el = np.radians(np.asarray(view, float))
    d = np.array([np.sin(az) * np.cos(el), np.sin(el), np.cos(az) * np.cos(el)])
    right = np.cross([0.0, 1.0, 0.0], d)
    right /= np.linalg.norm(right)
    return right, np.cross(d, right), d


def draw_mesh(ax, mesh: LipMesh, view="front", vertices=None, values=None, cmap="viridis",
              vmin=None, vmax=None, markers=True, anchors=True, nose=True, edges=True):
    """Draw ``mesh`` into a matplotlib axis; returns the surface's PolyCollection.

    Parameters
    ----------
    ax : matplotlib Axes
    mesh : LipMesh
    view : str or (float, float)
        A name in :data:`VIEWS` or (azimuth, elevation) in degrees.
    vertices : (n, 3) float, optional
        Positions to draw instead of the rest positions (a deformed mesh), mm.
    values : (n,) float, optional
        Per-vertex values shown through ``cmap`` instead of the region colours.
    markers, anchors, nose, edges : bool
        Overlay the numbered markers (1-based, thesis order; markers facing away are faded),
        the anchors, the nose point, and the triangle edges.
    """
    from matplotlib import colormaps
    from matplotlib.collections import PolyCollection
    from matplotlib.colors import Normalize, to_rgb

    V = mesh.vertices if vertices is None else as_float_array(vertices, "vertices", (mesh.n_nodes, 3))
    right, up, toward = _camera(view)
    xy = np.stack([V @ right, V @ up], axis=1)
    tri = V[mesh.faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    light = toward + 0.5 * up
    shade = 0.35 + 0.65 * np.abs(normal @ (light / np.linalg.norm(light)))
    if values is None:
        base = np.array([to_rgb(REGION_COLORS.get(name, "#999999")) for name in mesh.region_names])
        rgb = base[mesh.regions]
        mappable = None
    else:
        vals = as_float_array(values, "values", (mesh.n_nodes,))
        norm = Normalize(vmin if vmin is not None else vals.min(), vmax if vmax is not None else vals.max())
        rgb = colormaps[cmap](norm(vals[mesh.faces].mean(axis=1)))[:, :3]
        mappable = (norm, cmap)
    rgb = rgb * shade[:, None]
    order = np.argsort((tri @ toward).mean(axis=1))
    coll = PolyCollection(xy[mesh.faces[order]], facecolors=rgb[order],
                          edgecolors=(0, 0, 0, 0.25) if edges else "none", linewidths=0.3)
    ax.add_collection(coll)
    if markers and len(mesh.markers):
        facing = mesh.with_vertices(V).vertex_normals()[mesh.markers] @ toward > 0
        pm = xy[mesh.markers]
        for k, (p, vis) in enumerate(zip(pm, facing, strict=True)):
            alpha = 1.0 if vis else 0.3
            ax.plot(*p, "o", ms=4, color="#1f4fd1", alpha=alpha, zorder=5)
            ax.annotate(str(k + 1), p, xytext=(3, 3), textcoords="offset points", fontsize=7,
                        color="#0b2a80", alpha=alpha, zorder=6)
    if anchors and len(mesh.anchors):
        pa = xy[mesh.anchors]
        ax.plot(pa[:, 0], pa[:, 1], "x", ms=4, color="k", zorder=5, label="anchors")
    if nose:
        pn = np.array([mesh.nose @ right, mesh.nose @ up])
        ax.plot(*pn, "*", ms=10, color="#2a9d3a", zorder=5, label="nose")
    pts = [xy] + ([pn[None]] if nose else [])
    allp = np.concatenate(pts)
    pad = 0.05 * np.ptp(allp, axis=0).max()
    ax.set_xlim(allp[:, 0].min() - pad, allp[:, 0].max() + pad)
    ax.set_ylim(allp[:, 1].min() - pad, allp[:, 1].max() + pad)
    ax.set_aspect("equal")
    coll.lipgen_mappable = mappable
    return coll


def plot_mesh(mesh: LipMesh, path: str | os.PathLike | None = None, views=("front", "profile"),
              vertices=None, values=None, title: str | None = None, value_label: str = "",
              **draw_kw):
    """A figure of ``mesh`` from several views; saved to ``path`` (PNG, atomically) if given.

    Parameters
    ----------
    mesh : LipMesh
    path : path, optional
        Where to save the picture. The folder must exist.
    views : sequence
        View names or (azimuth, elevation) pairs, one panel each.
    vertices : (n, 3) float, optional
        Deformed positions to draw instead of the rest shape.
    values : (n,) float, optional
        Per-vertex values to colour by (a colour bar labelled ``value_label`` is added).
    **draw_kw
        Passed to :func:`draw_mesh` (``markers``, ``anchors``, ``nose``, ``edges``, ``cmap``, ...).

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.cm import ScalarMappable
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    fig = Figure(figsize=(5.0 * len(views), 5.0), dpi=120, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(views), squeeze=False)[0]
    for ax, view in zip(axes, views, strict=True):
        coll = draw_mesh(ax, mesh, view, vertices=vertices, values=values, **draw_kw)
        ax.set_title(view if isinstance(view, str) else f"azimuth {view[0]:g}, elevation {view[1]:g}",
                     fontsize=9)
        ax.set_xlabel("mm", fontsize=8)
        ax.tick_params(labelsize=7)
    if values is None:
        handles = [Patch(color=REGION_COLORS.get(n, "#999999"), label=n) for n in mesh.region_names
                   if mesh.region_mask(n).any()]
        handles += axes[0].get_legend_handles_labels()[0]
        axes[0].legend(handles=handles, fontsize=7, loc="lower left")
    else:
        norm, cmap = coll.lipgen_mappable
        fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), ax=list(axes), label=value_label, shrink=0.8)
    n_markers = len(mesh.markers)
    marked = (f"markers numbered 1-{n_markers} in thesis order" if n_markers > 1 else
              "marker numbered 1" if n_markers == 1 else "no markers")
    fig.suptitle(title or f"{mesh.name}: {mesh.n_nodes} nodes, {mesh.n_faces} faces ({marked})",
                 fontsize=10)
    if path is not None:
        atomic_savefig(fig, path)
    return fig


def render_default_lips(out_dir: str | os.PathLike = "renders", resolution: int = 0) -> Path:
    """Draw the default lips (front, profile, oblique) to ``out_dir/lips_r{resolution}.png``."""
    from lipgen.mesh.procedural import lip_mesh

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"lips_r{resolution}.png"
    plot_mesh(lip_mesh(resolution), path, views=("front", "profile", "oblique"))
    return path
