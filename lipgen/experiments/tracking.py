"""The tracker measured against the truth over several datasets (``lipgen experiment tracking``).

Issue 15's targets, on accepted sightings (seen in both views with agreeing rays, not a pose
outlier: :func:`lipgen.evaluate.scoring.accepted_sightings`):

- tracking error <= 0.5 px RMS in each view (over its accepted sightings; both views must meet it);
- >= 97 % of the sightings the truth says are visible accepted (both views pooled);
- no accepted sighting more than 3 px from its true projection.

For each seed a dataset is generated (:func:`lipgen.dataset.generate.generate`, as ``lipgen
generate --preset P --seed S --frames F``) into the work folder and kept there, with a sidecar
naming the commit that generated it: a second run reuses it when its manifest holds the same
settings, seed, rig, frames, calibration and schema, and refuses (naming the differences) when it
holds others (:mod:`lipgen.experiments.tracking_inputs`). Or existing datasets are given. Each is
reconstructed as ``lipgen reconstruct`` does (:func:`lipgen.recon.pipeline.reconstruct_dataset`,
defaults): the accepted sightings need the normalisation's pose outliers, and the normalisation
and fields cost about 0.1 % of a hard set's reconstruction (0.13 of 102 s on hard seed 7), so
nothing is gained by stopping after the triangulation. Every sighting is scored with
:func:`lipgen.evaluate.scoring.sighting_errors` and :func:`~lipgen.evaluate.scoring.tracking_table`,
the definitions of ``lipgen evaluate``'s tracking table. The truth is read only to score.
"""

from __future__ import annotations

import logging
import os
import platform
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from lipgen._gitinfo import code_version
from lipgen.errors import DatasetError
from lipgen.evaluate.error_stats import OVER_PX, error_figures, share
from lipgen.experiments.tracking_inputs import (
    TrackingSettings,
    cached_dataset,
    check_inputs,
    generated_by,
    recon_file,
)
from lipgen.rig.camera import VIEWS

__all__ = ["TrackingSettings", "TARGETS", "set_figures", "targets_met", "pooled_figures", "spread",
           "run_tracking"]

log = logging.getLogger(__name__)

TARGETS = {"rms_px": 0.5, "accepted_share": 0.97, "over_3px": 0}
"""Issue 15's targets: RMS over the accepted sightings of each view (px, at most, in both views),
accepted share of the visible sightings (at least), accepted sightings more than 3 px off (at most)."""


def set_figures(ds_path: Path, recon) -> tuple[dict, dict]:
    """One set's figures (the evaluate tracking table per view, and both views pooled) and its
    accepted sightings' errors per view (px) for the picture.

    The visible sightings include the nose (the last of the P + 1 marks); ``markers_only`` gives
    the accepted share without it. Shares of nothing are NaN (:func:`~lipgen.evaluate.error_stats.share`)."""
    from lipgen.dataset.layout import Dataset
    from lipgen.evaluate.scoring import load_truth, sighting_errors, tracking_table

    ds = Dataset(ds_path)
    ds.require_truth("lipgen experiment tracking")
    if len(recon.uv[0]) != len(ds):
        raise DatasetError(f"the reconstruction has {len(recon.uv[0])} frames but {ds_path} {len(ds)}")
    truth = load_truth(ds)
    errs = sighting_errors(truth, recon)
    per_view = tracking_table(truth, recon, errs)
    ok_err = {v: e["err"][e["ok"]] for v, e in errs.items()}
    visible = int(sum(e["truly"].sum() for e in errs.values()))
    acc = np.concatenate(list(ok_err.values()))
    stats = error_figures(acc)
    F = len(ds)
    cpu = recon.info.get("cpu_seconds", {})
    marker_vis = int(sum(e["truly"][:, :-1].sum() for e in errs.values()))  # the nose is the last mark
    marker_acc = int(sum(e["ok"][:, :-1].sum() for e in errs.values()))
    fig = {"frames": F, "visible": visible, "accepted": int(len(acc)),
           "rejected": sum(t["rejected"] for t in per_view.values()),
           "lost": sum(t["lost"] for t in per_view.values()),
           "false_sightings": sum(t["false_sightings"] for t in per_view.values()),
           "within_3px": int(len(acc)) - stats["over_3px"], "over_3px": stats["over_3px"],
           "rms_px": stats["rms_px"], "p95_px": stats["p95_px"],
           "markers_only": {"visible": marker_vis, "accepted": marker_acc,
                            "accepted_share": share(marker_acc, marker_vis)},
           "tracking_cpu_ms_per_frame": 1000 * cpu["tracking"] / F if "tracking" in cpu else float("nan"),
           "tracking_wall_ms_per_frame": 1000 * recon.info["seconds"]["tracking"] / F,
           "calibration_cpu_s": cpu.get("calibration", float("nan")),
           "per_view": {v: {k: t[k] for k in ("rms_px", "p95_px", "tracked_share", "accepted", "rejected",
                                              "lost", "wrong_over_3px", "false_sightings")}
                        | {"visible": int(errs[v]["truly"].sum())} for v, t in per_view.items()}}
    fig["accepted_share"] = share(fig["accepted"], visible)
    fig["within_3px_share"] = share(fig["within_3px"], visible)
    fig["targets"] = targets_met(fig)
    return fig, ok_err


def failed_figures(ds_path: Path, reason: str) -> tuple[dict, dict]:
    """The figures of a set ``lipgen reconstruct`` could not reconstruct (``reason``): what a user gets
    from it is no accepted sighting, so its visible sightings (from the truth) count as not accepted
    (``not_reconstructed``; no rejected or lost counts, no errors, no CPU figure)."""
    from lipgen.dataset.layout import Dataset
    from lipgen.evaluate.scoring import load_truth

    ds = Dataset(ds_path)
    ds.require_truth("lipgen experiment tracking")
    vis = np.asarray(load_truth(ds)["visible"], dtype=bool)          # (F, 2, P + 1)
    nan = float("nan")
    per_view = {view: {"rms_px": nan, "p95_px": nan, "tracked_share": 0.0, "accepted": 0, "rejected": 0,
                       "lost": 0, "wrong_over_3px": 0, "false_sightings": 0, "visible": int(vis[:, v].sum())}
                for v, view in enumerate(VIEWS)}
    visible, marker_vis = int(vis.sum()), int(vis[:, :, :-1].sum())   # the nose is the last mark
    fig = {"frames": len(ds), "visible": visible, "accepted": 0, "rejected": 0, "lost": 0,
           "false_sightings": 0, "within_3px": 0, "over_3px": 0, "rms_px": nan, "p95_px": nan,
           "markers_only": {"visible": marker_vis, "accepted": 0, "accepted_share": share(0, marker_vis)},
           "tracking_cpu_ms_per_frame": nan, "tracking_wall_ms_per_frame": nan, "calibration_cpu_s": nan,
           "per_view": per_view, "not_reconstructed": {"sightings": visible, "reason": reason},
           "accepted_share": share(0, visible), "within_3px_share": share(0, visible)}
    fig["targets"] = dict.fromkeys(TARGETS, False)  # "none over 3 px" of nothing accepted is not met
    return fig, {view: np.zeros(0) for view in VIEWS}


def targets_met(fig: dict) -> dict:
    """Each of :data:`TARGETS` met (True) or not by figures ``fig``; the RMS target in every view
    (a NaN figure, e.g. no accepted sighting, does not meet its target)."""
    rms = [t["rms_px"] for t in fig["per_view"].values()]
    return {"rms_px": bool(rms) and all(bool(r <= TARGETS["rms_px"]) for r in rms),
            "accepted_share": bool(fig["accepted_share"] >= TARGETS["accepted_share"]),
            "over_3px": bool(fig["over_3px"] <= TARGETS["over_3px"])}


def pooled_figures(sets: list[dict], errors: list[dict]) -> dict:
    """All sightings of all sets together (each sighting weighs the same)."""
    keys = ("frames", "visible", "accepted", "rejected", "lost", "false_sightings", "within_3px", "over_3px")
    fig = {k: int(sum(s[k] for s in sets)) for k in keys}
    views = list(errors[0]) if errors else []
    per_view = {}
    for v in views:
        e = np.concatenate([er[v] for er in errors])
        st = error_figures(e)
        per_view[v] = {"rms_px": st["rms_px"], "p95_px": st["p95_px"], "accepted": int(len(e)),
                       "wrong_over_3px": st["over_3px"],
                       "visible": int(sum(s["per_view"][v]["visible"] for s in sets))}
        per_view[v]["tracked_share"] = share(per_view[v]["accepted"], per_view[v]["visible"])
    acc = np.concatenate([e for er in errors for e in er.values()]) if errors else np.zeros(0)
    st = error_figures(acc)
    fig["rms_px"], fig["p95_px"] = st["rms_px"], st["p95_px"]
    fig["accepted_share"] = share(fig["accepted"], fig["visible"])
    fig["within_3px_share"] = share(fig["within_3px"], fig["visible"])
    if all("markers_only" in s for s in sets):
        mv, ma = (sum(s["markers_only"][k] for s in sets) for k in ("visible", "accepted"))
        fig["markers_only"] = {"visible": mv, "accepted": ma, "accepted_share": share(ma, mv)}
    timed = [s for s in sets if np.isfinite(s["tracking_cpu_ms_per_frame"])]  # not the unreconstructed
    cpu = sum(s["tracking_cpu_ms_per_frame"] * s["frames"] for s in timed)
    frames = sum(s["frames"] for s in timed)
    fig["tracking_cpu_ms_per_frame"] = float(cpu / frames) if frames else float("nan")
    fig["not_reconstructed"] = [s["label"] for s in sets if "not_reconstructed" in s]
    fig["per_view"] = per_view
    fig["targets"] = targets_met(fig)
    return fig


def spread(sets: list[dict]) -> dict:
    """Mean, standard deviation (n - 1; NaN for one set), min and max over the sets of each figure
    (over the sets that have it: an unreconstructed set has no RMS or CPU figure)."""
    def pick(s, key):
        return s["per_view"][key[1]]["rms_px"] if isinstance(key, tuple) else s[key]

    keys = ["accepted_share", "within_3px_share", "over_3px", "rms_px", ("rms", "virtual"), ("rms", "real"),
            "tracking_cpu_ms_per_frame"]
    out = {}
    for key in keys:
        x = np.array([pick(s, key) for s in sets], dtype=float)
        x = x[np.isfinite(x)] if np.isfinite(x).any() else x
        name = f"rms_px_{key[1]}" if isinstance(key, tuple) else key
        std = float(np.std(x, ddof=1)) if len(x) > 1 else float("nan")
        out[name] = {"mean": float(np.mean(x)), "std": std, "min": float(np.min(x)), "max": float(np.max(x))}
    return out


def run_tracking(s: TrackingSettings, work, progress: bool = True, force: bool = False,
                 plan: list | None = None) -> dict:
    """Generate (or reuse) and reconstruct every set and score its tracking; the report's data.

    ``work`` is the folder of the generated datasets and the reconstructions (``LABEL.recon.npz``:
    what was measured, e.g. for ``lipgen evaluate --recon``); it is created if missing (its parent
    must exist). An existing reconstruction is refused before any work unless ``force``. A set that
    cannot be reconstructed (``DatasetError`` / ``ValueError``, e.g. the nose never seen in both views)
    is reported with the reason and scored by :func:`failed_figures`; the run goes on.
    ``plan``: :func:`~lipgen.experiments.tracking_inputs.check_inputs`'s answer when the caller
    has just checked (so that nothing is checked, or decoded, twice).
    """
    from lipgen.recon.pipeline import reconstruct_dataset

    work = Path(work)
    plan = check_inputs(s, work, force) if plan is None else plan
    if not work.parent.is_dir():
        raise FileNotFoundError(f"--work {work}: folder {work.parent} does not exist; create it first")
    work.mkdir(exist_ok=True)
    load, code = {"start": list(os.getloadavg())}, code_version()  # the code as it was when the run began
    t0, c0 = time.perf_counter(), time.process_time()
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(plan), desc="sets", unit="set")
    sets, errors = [], []
    for label, path, gs in plan:
        reused, made_by = None, None
        if gs is not None:
            path, reused = cached_dataset(path, gs, work, label, progress=progress)
            made_by = generated_by(work, label)
        try:
            recon = reconstruct_dataset(path, progress=progress)
        except (DatasetError, ValueError) as exc:  # e.g. the nose never seen in both views (a collapse)
            log.warning("%s: not reconstructed (%s); its visible sightings count as not accepted", label, exc)
            fig, err = failed_figures(path, str(exc))
        else:
            recon.save(recon_file(work, label))
            fig, err = set_figures(path, recon)
        fig.update(label=label, dataset=str(path), reused=reused, generated_by=made_by,
                   seed=gs.seed if gs is not None else _manifest_seed(path))
        sets.append(fig)
        errors.append(err)
        if bar is not None:
            bar.update()
    if bar is not None:
        bar.close()
    load["end"] = list(os.getloadavg())
    settings = asdict(s) | {"targets": TARGETS, "over_px": OVER_PX, "work": str(work)}
    if s.datasets:  # the sets are as they were made: no preset or frame count of this run
        settings |= {"preset": None, "frames": None}
    threads = {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS")}
    load |= {"seconds": time.perf_counter() - t0, "cpu_seconds": time.process_time() - c0, "threads": threads,
             "host": platform.node(), "cpu_count": os.cpu_count()}
    return {"settings": settings, "code": code, "sets": sets, "load": load,
            "pooled": pooled_figures(sets, errors), "spread": spread(sets), "errors": errors}


def _manifest_seed(path: Path):
    from lipgen.dataset.layout import Dataset

    return Dataset(path).manifest.get("seed")
