"""What ``lipgen experiment tracking`` measures, checked before any work: the settings, the given
or cached datasets (:func:`check_inputs`), and the cache of generated sets in the work folder
(:func:`cached_dataset`, with a sidecar naming the commit that generated each set)."""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lipgen._gitinfo import code_version
from lipgen._io import atomic_write_json
from lipgen.errors import DatasetError

__all__ = ["TrackingSettings", "DEFAULT_SEEDS", "MIN_FRAMES", "MIN_CALIB_FRAMES", "dataset_settings",
           "check_inputs", "cached_dataset", "generated_by", "recon_file"]

log = logging.getLogger(__name__)

DEFAULT_SEEDS = (41, 42, 43)
"""The seeds ``lipgen experiment tracking`` generates when given neither seeds nor datasets."""
MIN_FRAMES = 3
"""Fewest frames a dataset may have: the normalisation takes its reference before a held-out tail."""
MIN_CALIB_FRAMES = 4
"""Fewest chessboard frames: the calibration needs the board in 4 frames of each view
(``min_images`` of :func:`lipgen.recon.calibrate.calibrate_rig`)."""


@dataclass(frozen=True)
class TrackingSettings:
    """What :func:`~lipgen.experiments.tracking.run_tracking` measures: generated sets (``seeds``)
    or existing ones (``datasets``); exactly one of the two is given."""

    preset: str = "hard"
    seeds: tuple[int, ...] = ()
    """Seeds of the generated sets (e.g. :data:`DEFAULT_SEEDS`); empty with ``datasets``."""
    frames: int = 40
    size: tuple[int, int] | None = None
    """Image size (W, H); None: the generator's default (640x480)."""
    calib_frames: int | None = None
    """Chessboard frames; None: the preset's (hard: 40, the last 30 of them lens frames)."""
    lens_frames: int | None = None
    """Of the chessboard frames, how many show the lens board; None: the preset's when
    ``calib_frames`` is None too, else 0 (as ``lipgen generate``)."""
    datasets: tuple[str, ...] = ()
    """Existing dataset folders to score instead of generating ``seeds``."""


def dataset_settings(s: TrackingSettings, seed: int):
    """:class:`~lipgen.dataset.layout.GenerateSettings` of seed ``seed`` (``lipgen generate``'s)."""
    from lipgen.dataset.layout import GenerateSettings

    return GenerateSettings.from_preset(s.preset, frames=s.frames, seed=seed, size=s.size,
                                        calib_frames=s.calib_frames, lens_frames=s.lens_frames)


def recon_file(work: Path, label: str) -> Path:
    """Where the reconstruction of set ``label`` is saved."""
    return Path(work) / f"{label}.recon.npz"


def _sidecar(work: Path, label: str) -> Path:
    return Path(work) / f"{label}.generated.json"


def _label(s: TrackingSettings, i: int) -> str:
    # resolve: "--datasets ." is named after the folder, not ""
    return Path(s.datasets[i]).resolve().name if s.datasets else f"{s.preset}_s{s.seeds[i]}"


def check_inputs(s: TrackingSettings, work: Path, force: bool = False) -> list[tuple[str, Path, object]]:
    """Check every input before any work; returns (label, dataset folder, generator settings or
    None for a given dataset) per set. An existing ``LABEL.recon.npz`` in ``work`` is refused
    unless ``force``. Raises ``ValueError``/``DatasetError``/``FileExistsError`` naming the bad value."""
    from lipgen.dataset.presets import get_preset

    work = Path(work)
    if work.exists() and not work.is_dir():
        raise NotADirectoryError(f"--work {work} is a file, not a folder; choose a folder")
    if s.datasets and s.seeds:
        raise ValueError("give --seeds (generated sets) or --datasets (existing sets), not both")
    if s.datasets:
        out = [(_label(s, i), Path(p), None) for i, p in enumerate(s.datasets)]
        names = [label for label, _, _ in out]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"--datasets: two folders share the name {twice[0]!r} (the report names sets by "
                             "folder name); rename one")
        for _, path, _ in out:
            _check_given(path)
    else:
        get_preset(s.preset)
        if not s.seeds:
            raise ValueError(f"give at least one seed (--seeds {' '.join(map(str, DEFAULT_SEEDS))}) or "
                             "--datasets")
        bad = [x for x in s.seeds if isinstance(x, bool) or not isinstance(x, int | np.integer) or x < 0]
        if bad:
            raise ValueError(f"--seeds must be whole numbers >= 0, got {bad[0]!r}")
        if len(set(s.seeds)) != len(s.seeds):
            raise ValueError(f"--seeds {list(s.seeds)} repeats a seed; each set is one seed")
        if isinstance(s.frames, bool) or not isinstance(s.frames, int) or s.frames < MIN_FRAMES:
            raise ValueError(f"--frames must be a whole number >= {MIN_FRAMES}, got {s.frames!r}")
        out = []
        for i, seed in enumerate(s.seeds):
            gs = dataset_settings(s, seed)  # checks size, calibration and lens frames
            if gs.calib_frames - gs.lens_frames < MIN_CALIB_FRAMES:
                raise ValueError(f"--calib-frames {gs.calib_frames} with {gs.lens_frames} lens frames leaves "
                                 f"{gs.calib_frames - gs.lens_frames} frames of the calibration board; the "
                                 f"calibration needs at least {MIN_CALIB_FRAMES}")
            path = work / _label(s, i)
            _check_cache(path, gs)
            out.append((_label(s, i), path, gs))
    kept = [str(recon_file(work, label)) for label, _, _ in out if recon_file(work, label).exists()]
    if kept and not force:
        raise FileExistsError(f"--work {work} already holds {', '.join(kept)} (a reconstruction a run "
                              "measured); choose another --work or pass --force to replace them")
    return out


def _check_given(path: Path) -> None:
    """A given dataset must be whole, with truth, at least :data:`MIN_FRAMES` frames, a calibration
    and marks that match its mesh: else the run would fail after reconstructing the sets before it."""
    from lipgen.dataset.layout import Dataset, calib_paths, intact

    if not (path / "manifest.json").is_file():
        raise DatasetError(f"--datasets {path} is not a lipgen dataset (no manifest.json); give folders "
                           "written by lipgen generate")
    ds = Dataset(path)
    ds.require_truth("lipgen experiment tracking")
    if len(ds) < MIN_FRAMES:
        raise DatasetError(f"--datasets {path} has {len(ds)} frames; the reconstruction needs at least "
                           f"{MIN_FRAMES}")
    missing = ds.missing(truth=True)
    if missing:
        raise DatasetError(f"--datasets {path}: {len(missing)} frame{'s are' if len(missing) > 1 else ' is'} "
                           f"missing (e.g. frame {missing[0]}); finish it with lipgen generate --resume")
    n_cal = len(ds.manifest["calibration"]["frames"])
    if n_cal < MIN_CALIB_FRAMES:
        raise DatasetError(f"--datasets {path} has {n_cal} calibration frames; the calibration needs at "
                           f"least {MIN_CALIB_FRAMES}")
    from lipgen.dataset.manifest import CALIB_KIND

    for i in range(n_cal):
        for p, kind in zip(calib_paths(path, i), (None, CALIB_KIND), strict=True):
            if not intact(p, kind):
                raise DatasetError(f"--datasets {path}: calibration file {p} is missing or does not decode; "
                                   "finish the dataset with lipgen generate --resume")
    mesh = ds.manifest["mesh"]
    if not intact(path / mesh["file"], "lipgen.LipMesh"):
        raise DatasetError(f"--datasets {path}: {mesh['file']} is missing or does not decode")
    if ds.manifest.get("marks") != [*mesh["marker_names"], "nose"]:
        raise DatasetError(f"--datasets {path}: the manifest's marks {ds.manifest.get('marks')} are not the "
                           f"mesh's markers {mesh['marker_names']} and the nose; the truth cannot be matched")


def _check_cache(path: Path, gs) -> bool:
    """Whether ``path`` holds the dataset of settings ``gs`` (complete or not); False when it is
    absent, empty, or holds only a killed first run's temporary files. A folder holding anything
    else, or a dataset whose settings, seed, rig, frames, calibration or schema differ:
    :class:`DatasetError`, nothing touched."""
    from lipgen.dataset.film import rig_for
    from lipgen.dataset.folder import check_folder, check_same_dataset
    from lipgen.dataset.manifest import settings_entries
    from lipgen.rig.camera import default_rig

    old = check_folder(path, resume=True, option="--work")
    if old is None:
        return False
    # the mesh entry needs the simulated subject; it follows from the settings and seed compared here
    new = json.loads(json.dumps(settings_entries(gs, rig_for(gs.size, gs.conditions, default_rig))))
    check_same_dataset(path, old, new, option="--work")
    return True


def generated_by(work: Path, label: str) -> dict | None:
    """The code that generated the cached set ``label`` (its sidecar ``LABEL.generated.json``:
    :func:`lipgen._gitinfo.code_version`); None when there is no sidecar."""
    try:
        return json.loads(_sidecar(work, label).read_text())
    except (OSError, ValueError):
        return None


def cached_dataset(path: Path, gs, work: Path, label: str, progress: bool = False) -> tuple[Path, bool]:
    """The dataset of settings ``gs`` at ``path``: generated (or finished) unless it is there whole.

    Returns (path, whether it was reused as it was). A set this writes gets the sidecar
    ``WORK/LABEL.generated.json`` naming the code that wrote it; a reused one whose sidecar names
    another commit than the current one (or has none) is logged as a warning."""
    from lipgen.dataset.generate import generate
    from lipgen.dataset.layout import Dataset

    started = _check_cache(path, gs)
    if started and not Dataset(path).missing(truth=True):
        was, now = generated_by(work, label), code_version()
        if was is None:
            log.warning("%s: reused, generated by an unknown commit (no %s)", label,
                        _sidecar(work, label).name)
        elif was.get("git_commit") != now["git_commit"]:
            log.warning("%s: reused, generated at commit %s, the code is now at %s", label,
                        was.get("git_commit"), now["git_commit"])
        return path, True
    generate(path, gs, workers=1, resume=started, progress=progress)
    atomic_write_json(_sidecar(work, label), code_version() | {"finished_a_partial_set": started})
    return path, False
