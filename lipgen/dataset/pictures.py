"""Pictures comparing datasets: the same frame under two image conditions, side by side."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lipgen.dataset.layout import Dataset

__all__ = ["preset_of", "save_side_by_side", "easy_twin", "save_beside_easy"]


def preset_of(ds: Dataset) -> str:
    """The preset whose image conditions ``ds`` was made with, or ``"custom"``."""
    from lipgen.dataset.presets import PRESETS

    cond = ds.settings.conditions
    for name, preset in PRESETS.items():
        if preset.image.conditions == cond:
            return name
    return "custom"


def save_side_by_side(datasets: list[Dataset], index: int, out, zoom: bool = True) -> Path:
    """Save frame ``index`` of each dataset side by side, each titled with its preset, with the
    truth projections of the visible marks as small circles; ``zoom`` adds a row of close-ups of
    the mouth in the direct view (where the texture, blur and noise show).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt


    for ds in datasets:
        if not 0 <= index < len(ds):
            raise ValueError(f"frame {index} is out of range: {ds.path} has frames 0..{len(ds) - 1}")
        ds.require_truth("lipgen show --beside (it draws the truth marks)")
    rows = 2 if zoom else 1
    fig, axes = plt.subplots(rows, len(datasets), figsize=(6.4 * len(datasets), 4.8 * rows), squeeze=False)
    for j, ds in enumerate(datasets):
        frame = ds[index]
        uv, vis = frame.truth["uv_raw"], frame.truth["visible"]
        for r in range(rows):
            ax = axes[r, j]
            ax.imshow(frame.image, interpolation="nearest")
            for v in range(2):
                ax.scatter(uv[v, vis[v], 0], uv[v, vis[v], 1], s=40 if r else 14, facecolors="none",
                           edgecolors="lime", linewidths=0.6)
            ax.axis("off")
            if r == 0:
                ax.set_title(f"{ds.path.name}: preset {preset_of(ds)}, frame {frame.index}", fontsize=10)
            else:  # the mouth in the direct view
                _zoom_on(ax, uv[1, :-1][vis[1, :-1]])
                ax.set_title("mouth, direct view (circles: truth)", fontsize=9)
    return _save(fig, out)


def easy_twin(ds: Dataset, index: int) -> np.ndarray:
    """(H, W, 3) uint8: frame ``index`` of ``ds`` rendered again as the ``easy`` preset films it (the
    ideal camera, plain face, fixed light, perfect dots, no noise), from the frame's true shape and
    head pose: what the dataset's conditions changed. Needs pyrender."""
    from lipgen.rig.camera import default_rig
    from lipgen.rig.render import RigRenderer
    from lipgen.subject.face import FaceLook, FaceModel

    if not 0 <= index < len(ds):
        raise ValueError(f"frame {index} is out of range: {ds.path} has frames 0..{len(ds) - 1}")
    truth = ds[index].truth
    face = FaceModel(ds.mesh, FaceLook(dot_diameter=ds.settings.dot_diameter), dots=ds.dots)
    rig = default_rig(*ds.settings.size)
    with RigRenderer(rig) as r:
        return r.render(face.scene(truth["vertices"], truth["pose"])).image


def save_beside_easy(ds: Dataset, index: int, out) -> Path:
    """Save frame ``index`` of ``ds`` beside its :func:`easy_twin`, with close-ups of the mouth in the
    direct view (where the head, teeth, ink, shadows, blur and noise show)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt


    easy = easy_twin(ds, index)
    frame = ds[index]
    uv, vis = frame.truth["uv_raw"], frame.truth["visible"]
    real = uv[1, :-1][vis[1, :-1]]
    fig, axes = plt.subplots(2, 2, figsize=(12.8, 9.6), squeeze=False)
    for j, (img, title) in enumerate(((frame.image, f"{ds.path.name}: preset {preset_of(ds)}"),
                                      (easy, "the same frame, preset easy"))):
        for r in range(2):
            ax = axes[r, j]
            ax.imshow(img, interpolation="nearest")
            ax.axis("off")
            if r == 0:
                ax.set_title(f"{title}, frame {frame.index}", fontsize=10)
            elif len(real):
                _zoom_on(ax, real)
                ax.set_title("mouth, direct view", fontsize=9)
    return _save(fig, out)


def _zoom_on(ax, points: np.ndarray) -> None:
    """Frame ``ax`` on the mean of ``points`` ((k, 2) px; nothing when empty): the mouth close-up."""
    if len(points):
        c = np.nanmean(points, axis=0)
        ax.set_xlim(c[0] - 90, c[0] + 90)
        ax.set_ylim(c[1] + 60, c[1] - 60)


def _save(fig, out) -> Path:
    """Write ``fig`` to ``out`` atomically (format from the suffix, png by default) and close it."""
    import matplotlib.pyplot as plt

    from lipgen._io import atomic_savefig

    fig.tight_layout()
    out = Path(out)
    atomic_savefig(fig, out, dpi=100)
    plt.close(fig)
    return out
