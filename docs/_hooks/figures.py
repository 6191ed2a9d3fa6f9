"""MkDocs hook: the pictures of the site, made by lipgen itself before the pages are read.

Everything goes into ``docs/figures/`` (git-ignored): the lips and their regions, the thesis's
Fig 2-2, the named forces, a whole demo run (raw frame with tracked and true dots, modes, the
Table 5.1 report) and an NRSfM reconstruction against its truth. A stamp file keeps the figures
of one lipgen version; ``make docs-clean`` (or a new version) makes them again.
"""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
import time
from pathlib import Path

log = logging.getLogger("mkdocs.hooks.figures")

FIGURES = Path(__file__).resolve().parents[1] / "figures"
DEMO_FRAMES = 60


def on_pre_build(config, **kwargs) -> None:
    import lipgen

    stamp = FIGURES / ".stamp"
    if stamp.is_file() and stamp.read_text() == lipgen.__version__:
        return
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    t0 = time.perf_counter()
    if FIGURES.exists():
        shutil.rmtree(FIGURES)
    FIGURES.mkdir(parents=True)
    lips_figure(FIGURES / "lips.png")
    demo_figures(FIGURES)
    nrsfm_figure(FIGURES / "nrsfm.png")
    stamp.write_text(lipgen.__version__)
    log.info("figures made in %.0f s", time.perf_counter() - t0)


def lips_figure(path: Path) -> None:
    from lipgen.mesh import lip_mesh
    from lipgen.mesh.plot import plot_mesh

    plot_mesh(lip_mesh(1), path)


def demo_figures(out: Path) -> None:
    """A short demo run (physics pictures, generate, reconstruct, train, evaluate)."""
    from lipgen.commands import demo

    with tempfile.TemporaryDirectory() as tmp:
        demo.run(tmp, frames=DEMO_FRAMES, workers=1, progress=False)
        src = Path(tmp) / "demo"
        for name in ("physics_forces.png", "rest_state.png", "fig_2_2.png"):
            shutil.copy2(src / name, out / name)
        shutil.copytree(src / "report", out / "report")


def nrsfm_figure(path: Path) -> None:
    """Non-rigid SfM (``dai``) of a synthetic articulated body against its truth, three frames."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from scipy.linalg import orthogonal_procrustes

    from lipgen import nrsfm
    from lipgen.nrsfm.synthetic import articulated_sequence

    W, S, _ = articulated_sequence(120, np.random.default_rng(7))
    rec = nrsfm.reconstruct(W, 4, method="dai")
    F = W.shape[0] // 2
    est = rec.S.reshape(F, 3, -1) - rec.S.reshape(F, 3, -1).mean(2, keepdims=True)
    true = S.reshape(F, 3, -1) - S.reshape(F, 3, -1).mean(2, keepdims=True)
    # one orthogonal alignment for the whole sequence (as e3D does), reflection allowed
    A = np.concatenate(list(est), axis=1).T
    B = np.concatenate(list(true), axis=1).T
    Q, _ = orthogonal_procrustes(A, B)
    err = nrsfm.e3d(rec.S, S)
    fig, axes = plt.subplots(2, 3, figsize=(9, 5.6))
    for col, f in enumerate((0, F // 2, F - 1)):
        e, t = (est[f].T @ Q).T, true[f]
        for row, (i, j, label) in enumerate(((0, 1, "x-y (image)"), (0, 2, "x-z (depth)"))):
            ax = axes[row, col]
            ax.scatter(t[i], t[j], s=18, c="#333333", label="truth")
            ax.scatter(e[i], e[j], s=10, c="#e4572e", label="dai")
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(f"frame {f}, {label}", fontsize=9)
    axes[0, 0].legend(fontsize=8, loc="best")
    fig.suptitle(f"NRSfM (dai, K = 4) of a synthetic articulated body: e3D = {err:.3f}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
