"""Bench suite ``modes``: LLSE reconstruction throughput and mode fitting time.

Throughput is compared with a bare numpy matmul of the same shapes, timed in the same run: once
the gain is precomputed, reconstructing a batch of frames is that product plus an offset. The
combined model's scale mixture (``CombinedModel.mixture``) is timed against the same baseline: it
evaluates one gain per residual variance of its grid plus each frame's evidence, so it is slower
by about the grid size.
"""

from __future__ import annotations

import numpy as np

from lipgen.bench.measure import time_call

NAME = "modes"


def _fields(rng, F: int, D: int, rank: int = 30) -> np.ndarray:
    """Random smooth-spectrum displacement fields (F, D): timing does not depend on the values."""
    basis = rng.normal(size=(rank, D))
    return (rng.normal(size=(F, rank)) * np.geomspace(3.0, 0.01, rank)) @ basis


def _throughput(resolution: int, quick: bool, rng) -> dict:
    from lipgen import lip_mesh
    from lipgen.fem import dofs
    from lipgen.modes.model import ModeModel

    mesh = lip_mesh(resolution)
    D = mesh.n_dofs
    model = ModeModel(10).fit(_fields(rng, 150, D))
    est = model.llse(dofs(mesh.markers))  # 16 markers, x-y-z: 48 observed DOFs
    d = len(est.dofs)
    batch = max(64, int((1.5e6 if quick else 6e6) // D))  # output of about 12 / 48 MB
    Y = rng.normal(size=(batch, d))
    G = est.gain_t.copy()
    repeat = 3 if quick else 7
    t_llse = time_call(lambda: est(Y), repeat=repeat)["best_s"]
    t_bare = time_call(lambda: Y @ G, repeat=repeat)["best_s"]
    return {"resolution": resolution, "n_nodes": mesh.n_nodes, "observed_dofs": d, "batch": batch,
            "llse_frames_per_s": batch / t_llse, "matmul_frames_per_s": batch / t_bare,
            "llse_over_matmul_time": t_llse / t_bare}


def _combined(quick: bool, rng) -> dict:
    """Frames/s of the combined model at resolution 0: one-σ² LLSE and the scale mixture."""
    from lipgen import Physics, lip_mesh
    from lipgen.fem import dofs
    from lipgen.modes.combined import CombinedModel
    from lipgen.modes.model import ModeModel

    mesh = lip_mesh(0)
    cm = CombinedModel(ModeModel(10).fit(_fields(rng, 150, mesh.n_dofs)), Physics(mesh),
                       residual_share=0.05, noise_variance=0.01)
    d = dofs(mesh.markers)
    one, mix = cm.llse(d), cm.mixture(d)
    batch = 2000 if quick else 10000
    Y = rng.normal(size=(batch, len(d)))
    G = one.gain_t.copy()
    repeat = 3 if quick else 5
    t_one = time_call(lambda: one(Y), repeat=repeat)["best_s"]
    t_mix = time_call(lambda: mix(Y), repeat=repeat)["best_s"]
    t_bare = time_call(lambda: Y @ G, repeat=repeat)["best_s"]
    return {"batch": batch, "observed_dofs": len(d), "grid_size": len(mix.variances),
            "one_sigma_frames_per_s": batch / t_one, "mixture_frames_per_s": batch / t_mix,
            "matmul_frames_per_s": batch / t_bare, "mixture_over_one_sigma_time": t_mix / t_one,
            "mixture_over_matmul_time": t_mix / t_bare}


def _fit_time(quick: bool, rng) -> dict:
    from lipgen import lip_mesh
    from lipgen.modes.model import ModeModel

    D = lip_mesh(0).n_dofs
    F = 2000 if quick else 10000
    X = _fields(rng, F, D, rank=60) + 1e-3 * rng.normal(size=(F, D))
    t_fit = time_call(lambda: ModeModel(10).fit(X), repeat=3)["best_s"]
    # Baseline: a thin SVD of the centred frames, the textbook PCA route.
    t_svd = time_call(lambda: np.linalg.svd(X - X.mean(0), full_matrices=False), repeat=3)["best_s"]
    F_snap = 600
    t_snap = time_call(lambda: ModeModel(10, method="snapshot").fit(X[:F_snap]), repeat=3)["best_s"]
    return {"fit_frames": F, "n_dofs": D, "fit_s": t_fit, "svd_baseline_s": t_svd,
            "fit_over_svd_time": t_fit / t_svd, "snapshot_fit_frames": F_snap,
            "snapshot_fit_s": t_snap}


def run(quick: bool = False) -> dict:
    """LLSE frames/s at resolutions 0 and 3 (16 markers) and the combined model's at 0, against a
    bare matmul; fit time."""
    import os

    rng = np.random.default_rng(0)
    out = {"load_average": list(os.getloadavg())}
    for r in (0, 3):
        out[f"llse_res{r}"] = _throughput(r, quick, rng)
    out["combined_res0"] = _combined(quick, rng)
    out["fit"] = _fit_time(quick, rng)
    return out
