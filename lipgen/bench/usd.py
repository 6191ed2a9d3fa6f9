"""Benchmark suite ``usd``: USD export time and file size, ``.usdc`` against ``.usda``.

10 modes x 10,000 frames on the resolution-0 lips (target: 2 s or less for ``.usdc``). Every
format and encoding is timed in the same run; the baseline is ``numpy.save`` of the same
float32 arrays the file holds (the least any writer has to do), so the ratios say what the USD
structure costs on this machine whatever its load. Reading back (``read_animation``, UsdSkel's
``BakeSkinning`` over every frame) is timed as well, and its points are compared with the
float64 synthesis (the precision of USD's float32 evaluation at this scale).
"""

from __future__ import annotations

import io
import os
import tempfile
from pathlib import Path

import numpy as np

from lipgen.bench.measure import time_call

NAME = "usd"


def _setup(n_frames: int, n_modes: int = 10, seed: int = 0):
    from lipgen import lip_mesh
    from lipgen.modes.model import ModeModel

    mesh = lip_mesh(0)
    rng = np.random.default_rng(seed)
    n = mesh.n_nodes
    # Smooth random fields (a few Gaussian bumps) as training data; weights of the right spread.
    centres = mesh.vertices[rng.choice(n, 16, replace=False)]
    bumps = np.exp(-((mesh.vertices[None] - centres[:, None]) ** 2).sum(-1) / 100.0)
    train = np.einsum("fb,bn,bc->fnc", rng.normal(size=(4 * n_modes, 16)), bumps, rng.normal(size=(16, 3)))
    model = ModeModel(n_modes).fit(train, mesh=mesh)
    # Sums of sinusoids of random (incommensurate) frequencies, 0.2-3 Hz: never periodic, so the
    # crate format cannot shrink the file by sharing repeated samples.
    t = np.arange(n_frames) / 30.0
    freq = rng.uniform(0.2, 3.0, (3, n_modes))
    phase = rng.uniform(0, 2 * np.pi, (3, n_modes))
    wave = np.sin(2 * np.pi * freq[:, None] * t[None, :, None] + phase[:, None]).sum(0) / np.sqrt(3)
    weights = wave * np.sqrt(model.explained_variance_)
    return mesh, model, weights


def run(quick: bool = False) -> dict:
    from lipgen.usd.export import export_usd, read_animation

    n_frames = 1_000 if quick else 10_000
    mesh, model, weights = _setup(n_frames)
    points = mesh.vertices + model.synthesize(weights)
    out: dict = {"n_frames": n_frames, "n_modes": int(weights.shape[1]), "n_nodes": mesh.n_nodes,
                 "load_avg_1min": os.getloadavg()[0]}

    def baseline():
        buf = io.BytesIO()
        np.save(buf, weights.astype(np.float32))
        np.save(buf, points.astype(np.float32))
        return buf

    out["baseline_numpy_save_s"] = time_call(baseline, repeat=3)["best_s"]
    with tempfile.TemporaryDirectory(prefix="lipgen-bench-usd-") as work:
        for label, kw in (("modes", dict(model=model, weights=weights)),
                          ("baked", dict(points=points)),
                          ("both", dict(model=model, weights=weights, points=points))):
            for ext in (".usdc", ".usda"):
                path = Path(work) / f"{label}{ext}"
                timing = time_call(lambda p=path, k=kw: export_usd(p, mesh, fps=30, **k), repeat=3)
                key = f"{label}{ext.replace('.', '_')}"
                out[f"{key}_export_s"] = timing["best_s"]
                out[f"{key}_size_mb"] = path.stat().st_size / 1e6
                out[f"{key}_vs_baseline"] = timing["best_s"] / out["baseline_numpy_save_s"]
            for what, unit in (("time", "export_s"), ("size", "size_mb")):
                ratio = out[f"{label}_usda_{unit}"] / out[f"{label}_usdc_{unit}"]
                out[f"{label}_usda_over_usdc_{what}"] = ratio
        read = time_call(lambda: read_animation(Path(work) / "modes.usdc"), repeat=1)
        out["modes_usdc_read_animation_s"] = read["best_s"]
        # Precision of USD's own (float32) evaluation against the float64 synthesis, every frame.
        err = np.abs(read_animation(Path(work) / "modes.usdc").points - points)
        out["modes_usdskel_max_abs_err_mm"] = float(err.max())
        out["modes_usdskel_max_rel_err"] = float(err.max() / np.abs(points).max())
        out["float32_half_step_at_max_coord_mm"] = float(np.spacing(np.float32(np.abs(points).max())) / 2)
    out["target_usdc_export_s"] = 2.0
    out["modes_usdc_meets_target"] = bool(out["modes_usdc_export_s"] <= 2.0)
    out["load_avg_1min_after"] = os.getloadavg()[0]
    return out
