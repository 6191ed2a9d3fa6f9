"""The tasks of a campaign, as plain functions of paths and settings.

Each runs in a worker (a Ray task, or a local process) and writes its outputs atomically into
the item's folder (layout: :mod:`lipgen.campaign.store`); it returns a small JSON-able summary.
They are the same code paths as the commands ``lipgen generate / reconstruct / train /
evaluate`` and the NRSfM section of the report.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

__all__ = ["limit_threads", "prepare", "render_chunk", "reconstruct", "train", "evaluate", "nrsfm",
           "chunks", "run_stage", "STAGE_FUNCTIONS"]

def limit_threads() -> None:
    """One BLAS thread per task, and GL rasterizing in the rendering thread: a worker is given one
    core; more threads would oversubscribe it (``lipgen._threads.limit_worker_threads``)."""
    from lipgen._threads import limit_worker_threads

    limit_worker_threads(1)


def chunks(jobs: list, size: int) -> list[list]:
    """``jobs`` cut into runs of at most ``size``."""
    return [jobs[i:i + size] for i in range(0, len(jobs), size)]


def prepare(dataset: str, settings: dict):
    """Simulate the subject and lay out the dataset folder; returns (context, jobs still to do,
    seconds)."""
    from lipgen.dataset.generate import prepare_dataset
    from lipgen.dataset.layout import GenerateSettings

    limit_threads()
    t0 = time.perf_counter()
    ctx, jobs = prepare_dataset(dataset, GenerateSettings.from_dict(settings), resume=True)
    return ctx, jobs, time.perf_counter() - t0


def render_chunk(ctx, jobs: list) -> dict:
    """Render and write some frames of one dataset; returns frames, seconds, CPU seconds (all the
    worker's threads), pid and peak resident MiB."""
    from lipgen.dataset.generate import render_jobs

    limit_threads()
    t0, c0 = time.perf_counter(), time.process_time()
    n = render_jobs(ctx, [tuple(j) for j in jobs])
    return {"frames": n, "seconds": time.perf_counter() - t0, "cpu_seconds": time.process_time() - c0,
            "pid": os.getpid(), "peak_rss_mib": _peak_mib()}


def _peak_mib() -> float | None:
    try:
        import resource

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB on Linux
    except (ImportError, OSError):
        return None


def reconstruct(item: str, options: dict) -> dict:
    """``lipgen reconstruct`` of the item's dataset -> ``recon.npz``."""
    from lipgen.recon.pipeline import reconstruct_dataset

    limit_threads()
    d = Path(item)
    recon = reconstruct_dataset(d / "dataset", options.get("mesh", "lip_mesh(0)"), progress=False,
                                normalisation=options.get("normalisation", "least-force"))
    recon.save(d / "recon.npz")
    return {"visible_share": float(recon.visible.mean())}


def train(item: str, options: dict) -> dict:
    """``lipgen train`` on the item's reconstruction -> ``model.npz``."""
    from lipgen.evaluate.scoring import default_test_frames, split_frames
    from lipgen.modes.model import ModeModel
    from lipgen.recon.pipeline import Reconstruction, model_mesh

    limit_threads()
    d = Path(item)
    recon = Reconstruction.load(d / "recon.npz")
    T = options.get("test_frames") or default_test_frames(len(recon.fields))
    tr, _ = split_frames(recon.fields, T)
    mesh = model_mesh(recon.info["mesh_source"])
    model = ModeModel(options.get("modes", 10)).fit(recon.fields[tr], mesh=mesh)
    model.save(d / "model.npz")
    return {"train_frames": int(len(tr)), "modes": int(len(model.components_))}


def evaluate(item: str, options: dict) -> dict:
    """``lipgen evaluate`` of the item -> ``report/report.md`` and ``report/report.json``."""
    from lipgen.dataset.layout import Dataset
    from lipgen.evaluate.report import write_report
    from lipgen.evaluate.scoring import score
    from lipgen.modes.model import ModeModel
    from lipgen.recon.pipeline import Reconstruction, model_mesh

    limit_threads()
    d = Path(item)
    recon = Reconstruction.load(d / "recon.npz")
    mesh = model_mesh(recon.info["mesh_source"])
    ds, model = Dataset(d / "dataset"), ModeModel.load(d / "model.npz")
    s = score(ds, model, recon, options.get("test_frames"), mesh)
    write_report(d / "report", s, ds, model, recon, mesh)
    return {"triangulation_rms_mm": s["triangulation"]["rms_mm"]}


def nrsfm(item: str, options: dict) -> dict:
    """Monocular NRSfM on one view of the item's dataset (truth projections, and the tracker's
    tracks when the item was reconstructed) -> ``nrsfm.json``."""
    import numpy as np

    from lipgen._io import atomic_write_json
    from lipgen.nrsfm import evaluate_on_dataset
    from lipgen.rig.camera import VIEWS

    limit_threads()
    d = Path(item)
    view, k, method = options.get("view", "real"), options.get("k", 2), options.get("method", "dai")
    out = {"truth_tracks": evaluate_on_dataset(d / "dataset", view=view, k=k, method=method)}
    if (d / "recon.npz").is_file():
        from lipgen.recon.pipeline import Reconstruction
        from lipgen.recon.track import LOST

        recon = Reconstruction.load(d / "recon.npz")
        v = list(VIEWS).index(view)
        seen = np.isfinite(recon.uv[v]).all(axis=-1) & (recon.status[v] != LOST)
        out["tracked"] = evaluate_on_dataset(d / "dataset", view=view, k=k, method=method, uv=recon.uv[v],
                                             seen=seen)
    for r in out.values():
        r.pop("markdown", None)
    atomic_write_json(d / "nrsfm.json", out)
    return {"e3d": out["truth_tracks"]["e3d"]}


STAGE_FUNCTIONS = {"reconstruct": reconstruct, "train": train, "evaluate": evaluate, "nrsfm": nrsfm}
"""The task of each stage after generate, by name; each takes (item folder, options)."""


def run_stage(stage: str, item: str, options: dict) -> dict:
    """Run stage ``stage`` on an item; its summary gets ``task_seconds`` (work, not queueing)."""
    t0 = time.perf_counter()
    out = STAGE_FUNCTIONS[stage](item, options)
    return {**out, "task_seconds": time.perf_counter() - t0}
