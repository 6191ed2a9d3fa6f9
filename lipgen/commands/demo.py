"""``lipgen demo``: the default lips through the whole loop, with a report under ``--out``.

The demo is a plain sequence of steps, each a small function that returns what it wrote:
the physics pictures (named forces, the thesis's Fig 2-2), then the end-to-end experiment of
thesis chapters 3-5 on synthetic data: generate a camera-mirror dataset of the default subject
-> reconstruct (calibrate, track, triangulate, normalise, reach) -> train the modes -> evaluate
against the ground truth -> export the trained model (and the reconstructed motion) to USD.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

import numpy as np

from lipgen._validate import check_workers

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

    from lipgen._io import atomic_path
    from lipgen.mesh.plot import draw_mesh

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

    from lipgen import dofs
    from lipgen._io import atomic_path
    from lipgen.mesh.plot import draw_mesh

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
    from lipgen.fem.planar import fig_2_2, plot_fig_2_2

    return plot_fig_2_2(fig_2_2(), out / "fig_2_2.png")


def step_dataset(out: Path, frames: int, seed: int, workers: int, progress: bool) -> Path:
    """Generate the demo dataset, or reuse it if a complete one with the same settings is there."""
    from lipgen.dataset.generate import generate
    from lipgen.dataset.layout import Dataset, GenerateSettings
    from lipgen.errors import DatasetError

    folder = out / "dataset"
    settings = GenerateSettings(frames=frames, seed=seed)
    if (folder / "manifest.json").is_file():
        try:
            ds = Dataset(folder)
            if ds.settings == settings and not ds.missing():
                log.info("reusing the complete demo dataset in %s", folder)
                return folder
        except DatasetError as exc:
            log.info("the old demo dataset is not usable (%s); making a new one", exc)
        import shutil

        log.warning("replacing the demo's own earlier dataset %s (other settings or incomplete)", folder)
        shutil.rmtree(folder)
    generate(folder, settings, workers=workers, progress=progress)
    return folder


def step_reconstruct(dataset: Path, out: Path, progress: bool):
    from lipgen.recon.pipeline import reconstruct_dataset

    # the demo's subject has the model's shape (preset easy) and moves in gestures, not speech: the
    # model's rest is exact (lipgen.recon.restsource)
    recon = reconstruct_dataset(dataset, progress=progress, rest="model")
    recon.save(out / "recon.npz")
    return recon, out / "recon.npz"


def step_train(recon, out: Path):
    from lipgen.evaluate.scoring import default_test_frames, split_frames
    from lipgen.modes.model import ModeModel
    from lipgen.recon.pipeline import model_mesh

    train, _ = split_frames(recon.fields, default_test_frames(len(recon.fields)))
    mesh = model_mesh(recon.info["mesh_source"])
    model = ModeModel(10).fit(recon.fields[train], mesh=mesh)
    model.save(out / "model.npz")
    return model, mesh, out / "model.npz"


def step_usd(model, mesh, recon, out: Path) -> Path | None:
    """The trained modes as UsdSkel blend shapes, animated by the reconstructed motion."""
    from lipgen.errors import MissingDependencyError

    try:
        from lipgen.usd.export import export_usd, validate
    except (ImportError, MissingDependencyError) as exc:
        log.warning("no USD export: %s", exc)
        return None
    ok = np.all(np.isfinite(recon.fields.reshape(len(recon.fields), -1)), axis=1)
    weights = model.project(recon.fields[ok])
    path = export_usd(out / "lips.usda", mesh, model=model, weights=weights, fps=30)
    errors = [i for i in validate(path) if i.is_error]
    if errors:
        raise RuntimeError(f"the exported {path} fails USD validation: {errors[:3]}")
    return path


def run(out_dir: str | Path, resolution: int = 0, frames: int = 150, seed: int = 0, workers: int = 2,
        physics_only: bool = False, progress: bool = True) -> list[Path]:
    """Run every demo step; returns the files written (the report last)."""
    import os

    from lipgen.dataset.layout import Dataset, GenerateSettings
    from lipgen.evaluate.report import nrsfm_section, write_report
    from lipgen.evaluate.scoring import score

    if not physics_only:  # bad --frames/--seed/--workers: refused before the physics pictures, not after
        GenerateSettings(frames=frames, seed=seed)
        check_workers(workers)
    t0 = time.perf_counter()
    out = Path(out_dir) / "demo"
    out.mkdir(parents=True, exist_ok=True)
    written = []
    mesh, physics = step_physics(resolution)
    written.append(step_named_forces(mesh, physics, out))
    _rest, path = step_rest_state(mesh, physics, out)
    written.append(path)
    written.append(step_fig_2_2(out))
    if physics_only:
        return written
    times = {"physics pictures": time.perf_counter() - t0}
    t = time.perf_counter()
    dataset = step_dataset(out, frames, seed, workers, progress)
    times["generate"] = time.perf_counter() - t
    t = time.perf_counter()
    recon, path = step_reconstruct(dataset, out, progress)
    written.append(path)
    times["reconstruct"] = time.perf_counter() - t
    t = time.perf_counter()
    model, model_mesh, path = step_train(recon, out)
    written.append(path)
    times["train"] = time.perf_counter() - t
    t = time.perf_counter()
    usd = step_usd(model, model_mesh, recon, out)
    if usd is not None:
        written.append(usd)
    times["export USD"] = time.perf_counter() - t
    t = time.perf_counter()
    ds = Dataset(dataset)
    s = score(ds, model, recon, mesh=model_mesh)
    times["evaluate"] = time.perf_counter() - t
    t = time.perf_counter()
    nrsfm_text = nrsfm_section(ds, recon)
    times["non-rigid SfM"] = time.perf_counter() - t
    load = os.getloadavg()
    rows = "\n".join(f"| {k} | {v:.1f} |" for k, v in times.items())
    extra = {"Demo run": f"Generated {frames} frames (seed {seed}, {workers} worker(s)); "
             f"USD: `{usd.name if usd else 'not written'}`.\n\n| step | seconds |\n|---|---|\n{rows}\n"
             f"| total before the report | {time.perf_counter() - t0:.1f} |\n\nMachine load (1, 5, 15 min) "
             f"at the end: {load[0]:.2f}, {load[1]:.2f}, {load[2]:.2f} on {os.cpu_count()} CPUs."}
    extra["Non-rigid SfM on one view"] = nrsfm_text
    written.append(write_report(out / "report", s, ds, model, recon, model_mesh, extra))
    return written


def add_parser(sub) -> None:
    p = sub.add_parser(
        "demo",
        help="the whole loop on the default subject: physics pictures, dataset, reconstruction, "
        "modes, evaluation against the truth, USD; report in OUT/demo/report/",
        description="Build the default lips and their physics and draw them under named forces, "
        "deformed to a rest state from marker goals (thesis Fig 4-1) and the thesis's Fig 2-2; then "
        "generate a camera-mirror dataset of the default subject, reconstruct it from the images "
        "(calibrate, track, triangulate, normalise, reach), train the modes, evaluate every stage "
        "against the ground truth and export the model to USD. Everything goes to OUT/demo/; the "
        "report is OUT/demo/report/report.md.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--out", default="renders", help="output folder (pictures go to OUT/demo/)")
    p.add_argument("--resolution", type=int, default=0, choices=range(0, 5),
                   help="lip mesh resolution of the physics pictures (0: ~200 nodes; each step ~4x)")
    p.add_argument("--frames", type=int, default=150, help="frames of the demo dataset (the thesis's 150)")
    p.add_argument("--seed", type=int, default=0, help="seed of the demo dataset")
    p.add_argument("--workers", type=int, default=2, help="rendering processes")
    p.add_argument("--physics-only", action="store_true", help="only the physics pictures")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from lipgen.commands._output import check_folder_output

    check_folder_output(args.out, True)  # OUT/demo is the demo's own; OUT's parent must exist
    written = run(args.out, args.resolution, args.frames, args.seed, args.workers, args.physics_only,
                  not args.no_progress)
    for path in written:
        sys.stdout.write(f"wrote {path}\n")
    if not args.physics_only:
        sys.stdout.write(f"\nreport: {written[-1]}\n")
    return 0
