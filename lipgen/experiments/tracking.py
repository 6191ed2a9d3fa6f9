"""The tracker measured against the truth over several datasets (``lipgen experiment tracking``).

Issue 15's targets, on accepted sightings (seen in both views with agreeing rays, not a pose
outlier: :func:`lipgen.evaluate.scoring.accepted_sightings`):

- tracking error <= 0.5 px RMS (over the accepted sightings of both views);
- >= 97 % of the sightings the truth says are visible accepted (both views pooled);
- no accepted sighting more than 3 px from its true projection.

For each seed a dataset is generated (:func:`lipgen.dataset.generate.generate`, as ``lipgen
generate --preset P --seed S --frames F``) into the work folder and kept there: a second run reuses
it when its manifest holds the same settings, and refuses (naming the differing settings) when it
holds others. Or existing datasets are given. Each is reconstructed as ``lipgen reconstruct``
does (:func:`lipgen.recon.pipeline.reconstruct_dataset`, defaults): the accepted sightings need the
normalisation's pose outliers, and the normalisation and fields cost about 0.1 % of a hard set's
reconstruction (0.13 of 102 s on hard seed 7), so nothing is gained by stopping after the
triangulation. Every sighting is scored with :func:`lipgen.evaluate.scoring.sighting_errors` and
:func:`~lipgen.evaluate.scoring.tracking_table`, the definitions of ``lipgen evaluate``'s tracking
table. The truth is read only to score.
"""

from __future__ import annotations

import logging
import os
import platform
import subprocess
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from lipgen.errors import DatasetError

__all__ = ["TrackingSettings", "TARGETS", "dataset_settings", "check_inputs", "cached_dataset", "set_figures",
           "targets_met", "pooled_figures", "spread", "run_tracking", "code_version"]

log = logging.getLogger(__name__)

TARGETS = {"rms_px": 0.5, "accepted_share": 0.97, "over_3px": 0}
"""Issue 15's targets: RMS over accepted sightings (px, at most), accepted share of the visible
sightings (at least), accepted sightings more than 3 px off (at most)."""
MIN_FRAMES = 3
"""Fewest frames a dataset may have: the normalisation takes its reference before a held-out tail."""


@dataclass(frozen=True)
class TrackingSettings:
    """What :func:`run_tracking` measures: generated sets (``seeds``) or existing ones (``datasets``)."""

    preset: str = "hard"
    seeds: tuple[int, ...] = (41, 42, 43)
    frames: int = 40
    size: tuple[int, int] | None = None
    """Image size (W, H); None: the generator's default (640x480)."""
    calib_frames: int | None = None
    """Chessboard frames; None: the preset's."""
    datasets: tuple[str, ...] = ()
    """Existing dataset folders to score instead of generating ``seeds``."""


def dataset_settings(s: TrackingSettings, seed: int):
    """:class:`~lipgen.dataset.layout.GenerateSettings` of seed ``seed`` (``lipgen generate``'s)."""
    from lipgen.dataset.layout import GenerateSettings

    return GenerateSettings.from_preset(s.preset, frames=s.frames, seed=seed, size=s.size,
                                        calib_frames=s.calib_frames)


def _label(s: TrackingSettings, i: int) -> str:
    return Path(s.datasets[i]).name if s.datasets else f"{s.preset}_s{s.seeds[i]}"


def check_inputs(s: TrackingSettings, work: Path) -> list[tuple[str, Path, object]]:
    """Check every input before any work; returns (label, dataset folder, generator settings or
    None for a given dataset) per set. Raises ``ValueError``/``DatasetError`` naming the bad value."""
    from lipgen.dataset.layout import Dataset
    from lipgen.dataset.presets import get_preset

    if work.exists() and not work.is_dir():
        raise NotADirectoryError(f"--work {work} is a file, not a folder; choose a folder")
    if s.datasets:
        if s.seeds:
            raise ValueError("give --seeds (generated sets) or --datasets (existing sets), not both")
        out = []
        for p in s.datasets:
            path = Path(p)
            if not (path / "manifest.json").is_file():
                raise DatasetError(f"--datasets {p} is not a lipgen dataset (no manifest.json); give folders "
                                   "written by lipgen generate")
            ds = Dataset(path)
            ds.require_truth("lipgen experiment tracking")
            missing = ds.missing(truth=True)
            if missing:
                raise DatasetError(f"--datasets {p}: {len(missing)} frames are missing (e.g. frame "
                                   f"{missing[0]}); finish it with lipgen generate --resume")
            out.append((path.name, path, None))
        names = [label for label, _, _ in out]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"--datasets: two folders share the name {twice[0]!r} (the report names sets by "
                             "folder name); rename one")
        return out
    get_preset(s.preset)
    if not s.seeds:
        raise ValueError("give at least one seed (--seeds 41 42 43) or --datasets")
    bad = [x for x in s.seeds if isinstance(x, bool) or not isinstance(x, int | np.integer) or x < 0]
    if bad:
        raise ValueError(f"--seeds must be whole numbers >= 0, got {bad[0]!r}")
    if len(set(s.seeds)) != len(s.seeds):
        raise ValueError(f"--seeds {list(s.seeds)} repeats a seed; each set is one seed")
    if not isinstance(s.frames, int) or s.frames < MIN_FRAMES:
        raise ValueError(f"--frames must be a whole number >= {MIN_FRAMES}, got {s.frames!r}")
    out = []
    for i, seed in enumerate(s.seeds):
        gs = dataset_settings(s, seed)  # checks size and calibration frames
        path = work / _label(s, i)
        _check_cache(path, gs)
        out.append((_label(s, i), path, gs))
    return out


def _check_cache(path: Path, gs) -> bool:
    """Whether ``path`` holds the dataset of settings ``gs`` (complete or not); False when it is
    absent or empty. A folder holding anything else: :class:`DatasetError`, nothing touched."""
    import json

    if path.exists() and not path.is_dir():
        raise DatasetError(f"work folder entry {path} is a file, not a dataset folder; remove it or choose "
                           "another --work")
    if not path.is_dir() or not any(path.iterdir()):
        return False
    mf = path / "manifest.json"
    if not mf.is_file():
        raise DatasetError(f"{path} is not empty and holds no dataset (no manifest.json); remove it or "
                           "choose another --work (nothing was overwritten)")
    try:
        old = json.loads(mf.read_text()).get("settings", {})
    except (OSError, ValueError) as exc:
        raise DatasetError(f"{mf} is not readable JSON ({exc}); remove {path} or choose another "
                           "--work") from exc
    new = json.loads(json.dumps(gs.to_dict()))
    diff = sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))
    if diff:
        detail = "; ".join(f"{k} was {old.get(k)!r}, now {new.get(k)!r}" for k in diff if k != "conditions")
        raise DatasetError(f"{path} holds a dataset made with other settings ({', '.join(diff)}"
                           f"{': ' + detail if detail else ''}); it is never overwritten: remove it, or "
                           "choose another --work")
    return True


def cached_dataset(path: Path, gs, progress: bool = False) -> tuple[Path, bool]:
    """The dataset of settings ``gs`` at ``path``: generated (or finished) unless it is there whole.

    Returns (path, whether it was reused as it was)."""
    from lipgen.dataset.generate import generate
    from lipgen.dataset.layout import Dataset

    started = _check_cache(path, gs)
    if started and not Dataset(path).missing(truth=True):
        return path, True
    generate(path, gs, workers=1, resume=started, progress=progress)
    return path, False


def _share(a: int, b: int) -> float:
    return float(a / b) if b else float("nan")


def set_figures(ds_path: Path, recon) -> tuple[dict, dict]:
    """One set's figures (the evaluate tracking table per view, and both views pooled) and its
    accepted sightings' errors per view (px) for the picture."""
    from lipgen.dataset.layout import Dataset
    from lipgen.evaluate.scoring import load_truth, sighting_errors, tracking_table

    ds = Dataset(ds_path)
    ds.require_truth("lipgen experiment tracking")
    if len(recon.uv[0]) != len(ds):
        raise DatasetError(f"the reconstruction has {len(recon.uv[0])} frames but {ds_path} {len(ds)}")
    truth = load_truth(ds)
    per_view = tracking_table(truth, recon)
    errs = sighting_errors(truth, recon)
    ok_err = {v: e["err"][e["ok"]] for v, e in errs.items()}
    visible = int(sum(e["truly"].sum() for e in errs.values()))
    acc = np.concatenate(list(ok_err.values()))
    F = len(ds)
    cpu = recon.info.get("cpu_seconds", {})
    fig = {"frames": F, "visible": visible, "accepted": int(len(acc)),
           "rejected": sum(t["rejected"] for t in per_view.values()),
           "lost": sum(t["lost"] for t in per_view.values()),
           "false_sightings": sum(t["false_sightings"] for t in per_view.values()),
           "within_3px": int((acc <= 3).sum()), "over_3px": int((acc > 3).sum()),
           "rms_px": float(np.sqrt(np.mean(acc ** 2))) if len(acc) else float("nan"),
           "p95_px": float(np.percentile(acc, 95)) if len(acc) else float("nan"),
           "tracking_cpu_ms_per_frame": 1000 * cpu["tracking"] / F if "tracking" in cpu else float("nan"),
           "tracking_wall_ms_per_frame": 1000 * recon.info["seconds"]["tracking"] / F,
           "calibration_cpu_s": cpu.get("calibration", float("nan")),
           "per_view": {v: {k: t[k] for k in ("rms_px", "p95_px", "tracked_share", "accepted", "rejected",
                                              "lost", "wrong_over_3px", "false_sightings")}
                        | {"visible": int(errs[v]["truly"].sum())} for v, t in per_view.items()}}
    fig["accepted_share"] = _share(fig["accepted"], visible)
    fig["within_3px_share"] = _share(fig["within_3px"], visible)
    fig["targets"] = targets_met(fig)
    return fig, ok_err


def targets_met(fig: dict) -> dict:
    """Each of :data:`TARGETS` met (True) or not by figures ``fig``."""
    return {"rms_px": bool(fig["rms_px"] <= TARGETS["rms_px"]),
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
        per_view[v] = {"rms_px": float(np.sqrt(np.mean(e ** 2))) if len(e) else float("nan"),
                       "p95_px": float(np.percentile(e, 95)) if len(e) else float("nan"),
                       "accepted": int(len(e)), "wrong_over_3px": int((e > 3).sum())}
        per_view[v]["visible"] = int(sum(s["per_view"][v]["visible"] for s in sets))
        per_view[v]["tracked_share"] = _share(per_view[v]["accepted"], per_view[v]["visible"])
    acc = np.concatenate([e for er in errors for e in er.values()]) if errors else np.zeros(0)
    fig["rms_px"] = float(np.sqrt(np.mean(acc ** 2))) if len(acc) else float("nan")
    fig["p95_px"] = float(np.percentile(acc, 95)) if len(acc) else float("nan")
    fig["accepted_share"] = _share(fig["accepted"], fig["visible"])
    fig["within_3px_share"] = _share(fig["within_3px"], fig["visible"])
    cpu = sum(s["tracking_cpu_ms_per_frame"] * s["frames"] for s in sets)
    fig["tracking_cpu_ms_per_frame"] = float(cpu / fig["frames"]) if fig["frames"] else float("nan")
    fig["per_view"] = per_view
    fig["targets"] = targets_met(fig)
    return fig


def spread(sets: list[dict]) -> dict:
    """Mean, standard deviation (n - 1; NaN for one set), min and max over the sets of each figure."""
    def pick(s, key):
        return s["per_view"][key[1]]["rms_px"] if isinstance(key, tuple) else s[key]

    keys = ["accepted_share", "within_3px_share", "over_3px", "rms_px", ("rms", "virtual"), ("rms", "real"),
            "tracking_cpu_ms_per_frame"]
    out = {}
    for key in keys:
        x = np.array([pick(s, key) for s in sets], dtype=float)
        name = f"rms_px_{key[1]}" if isinstance(key, tuple) else key
        std = float(np.std(x, ddof=1)) if len(x) > 1 else float("nan")
        out[name] = {"mean": float(np.mean(x)), "std": std, "min": float(np.min(x)), "max": float(np.max(x))}
    return out


def code_version() -> dict:
    """lipgen's version and, in a git checkout, the commit and whether the tree had changes."""
    from lipgen import __version__

    here = Path(__file__).resolve().parents[2]
    out = {"lipgen": __version__, "git_commit": None, "git_dirty": None}
    try:
        run = {"capture_output": True, "text": True, "timeout": 10, "check": True}
        git = ["git", "-C", str(here)]
        out["git_commit"] = subprocess.run([*git, "rev-parse", "HEAD"], **run).stdout.strip()
        status = subprocess.run([*git, "status", "--porcelain", "--untracked-files=no"], **run)
        out["git_dirty"] = bool(status.stdout.strip())
    except (OSError, subprocess.SubprocessError):
        pass
    return out


def run_tracking(s: TrackingSettings, work, progress: bool = True) -> dict:
    """Generate (or reuse) and reconstruct every set and score its tracking; the report's data.

    ``work`` is the folder of the generated datasets and the reconstructions (``LABEL.recon.npz``,
    rewritten each run: they are what was measured, e.g. for ``lipgen evaluate --recon``).
    """
    from lipgen.recon.pipeline import reconstruct_dataset

    work = Path(work)
    plan = check_inputs(s, work)
    load, code = {"start": list(os.getloadavg())}, code_version()  # the code as it was when the run began
    t0, c0 = time.perf_counter(), time.process_time()
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(plan), desc="sets", unit="set")
    sets, errors = [], []
    for label, path, gs in plan:
        reused = None
        work.mkdir(parents=True, exist_ok=True)  # after every check: a refused run writes nothing
        if gs is not None:
            path, reused = cached_dataset(path, gs, progress=progress)
        recon = reconstruct_dataset(path, progress=progress)
        recon.save(work / f"{label}.recon.npz")
        fig, err = set_figures(path, recon)
        fig.update(label=label, dataset=str(path), reused=reused,
                   seed=gs.seed if gs is not None else _manifest_seed(path))
        sets.append(fig)
        errors.append(err)
        if bar is not None:
            bar.update()
    if bar is not None:
        bar.close()
    load["end"] = list(os.getloadavg())
    settings = asdict(s) | {"targets": TARGETS, "work": str(work)}
    threads = {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS")}
    load |= {"seconds": time.perf_counter() - t0, "cpu_seconds": time.process_time() - c0, "threads": threads,
             "host": platform.node(), "cpu_count": os.cpu_count()}
    return {"settings": settings, "code": code, "sets": sets, "load": load,
            "pooled": pooled_figures(sets, errors), "spread": spread(sets), "errors": errors}


def _manifest_seed(path: Path):
    from lipgen.dataset.layout import Dataset

    return Dataset(path).manifest.get("seed")
