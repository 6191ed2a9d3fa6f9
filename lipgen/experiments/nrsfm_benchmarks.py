"""NRSfM on the standard sequences (drink, jaws) beside the published figures, and on synthetic
articulated sequences: e3D, reprojection, time. Writes ``benchmarks.md``, ``benchmarks.json`` and
the reprojection curves."""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lipgen._io import atomic_write_bytes, atomic_write_json

__all__ = ["DEFAULT_DATA", "PUBLISHED", "NrsfmBenchSettings", "run_nrsfm_benchmarks", "data_dir"]

log = logging.getLogger(__name__)

DEFAULT_DATA = "/work/shared/benchmarks/nrsfm"
"""Where the benchmark sequences live unless ``LIPGEN_NRSFM_DATA`` says otherwise."""

PUBLISHED = {
    "drink": [("Akhter et al. 2008, trajectory basis", 13, 0.025),
              ("Dai, Li & He 2012, block matrix method", 12, 0.027)],
    "jaws": [],
}
"""Published e3D figures per sequence: (source, K, e3D)."""

SEQUENCE_KS = {"drink": (12, 13), "jaws": (2, 3)}
"""K tried besides the automatic choice: the published Ks for drink; for jaws K = 2 (as it is
usually run) and K = 3 (its true number of basis shapes: mean plus two rank-1 deformations, which
is why the tracks are exactly rank 5). The least-trace-norm shapes are not of rank 3 there (the
relaxation is not tight); `dai`'s rank-K fit with the rotations fixed recovers jaws at K = 3 to
e3D ~0.002 (the remainder: a few frames view a deformation end-on, so its weight is unobservable)."""


MODE_KS = {"drink": (5, 11, 12), "jaws": (1, 2, 3, 5)}
"""K of the methods that count deformation modes beyond a mean shape (em-ppca; K + 1 basis shapes):
K = 2 on jaws is how Torresani et al.'s own shark demo runs it; on drink (41 points) K <= 12, since
3(K + 1) <= P - 1, so em-ppca K = 11, 12 match dai K = 12, 13 in model size."""


def data_dir() -> Path:
    """The folder of the benchmark sequences (``LIPGEN_NRSFM_DATA``, else the default)."""
    return Path(os.environ.get("LIPGEN_NRSFM_DATA", DEFAULT_DATA))


@dataclass(frozen=True)
class NrsfmBenchSettings:
    """What ``lipgen experiment nrsfm`` runs: methods, sequences and basis sizes."""
    methods: tuple[str, ...] = ("bregler", "dai", "dai-ba", "em-ppca")
    sequences: tuple[str, ...] = ("drink", "jaws")
    synthetic_seeds: tuple[int, ...] = (0, 1, 2, 3)
    synthetic_k: int = 6
    synthetic_frames: int = 600
    kmax: int = 13
    rtol: float = 0.01
    long_em_iter: int = 2000


def _load(name: str):
    path = data_dir() / f"{name}.npz"
    if not path.is_file():
        return None
    with np.load(path, allow_pickle=False) as d:
        return d["W"], d["S"]


def _run_one(W, S, k, method, **options) -> dict:
    from lipgen.nrsfm import e3d, n_basis_shapes, reconstruct

    t0 = time.perf_counter()
    rec = reconstruct(W, k, method=method, **options)
    seconds = time.perf_counter() - t0
    label = method + "".join(f" ({key}={value})" for key, value in options.items())
    return {"method": method, "label": label, "k": int(k), "n_basis": n_basis_shapes(int(k), method),
            "e3d": e3d(rec.S, S), "seconds": seconds,
            "reprojection_rms": rec.reprojection_rms,
            "relative_reprojection": rec.reprojection_rms / float(np.sqrt(np.mean(
                (W - W.mean(1, keepdims=True)) ** 2)))}


def run_nrsfm_benchmarks(out, settings: NrsfmBenchSettings = NrsfmBenchSettings()) -> dict:
    """Run everything, write the report into folder ``out``, return the figures."""
    from lipgen.nrsfm import MEAN_PLUS_MODES, plot_curve, reprojection_curve
    from lipgen.nrsfm.synthetic import articulated_sequence

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    result = {"load_before": os.getloadavg(), "sequences": {}, "synthetic": [],
              "settings": settings.__dict__, "data": str(data_dir())}
    for name in settings.sequences:
        data = _load(name)
        if data is None:
            log.warning("no %s.npz under %s; skipped", name, data_dir())
            continue
        W, S = data
        curve = reprojection_curve(W, ks=range(1, settings.kmax + 1), rtol=settings.rtol, progress=True)
        plot_curve(curve, out / f"{name}_curve.png")
        ks = sorted(set(SEQUENCE_KS.get(name, ())) | {curve.chosen})
        runs = [_run_one(W, S, k, m) for k in ks for m in settings.methods if m not in MEAN_PLUS_MODES]
        for r in runs:
            r["auto"] = r["k"] == curve.chosen
        for m in (m for m in settings.methods if m in MEAN_PLUS_MODES):
            runs += [dict(_run_one(W, S, k, m), auto=False) for k in MODE_KS.get(name, ())]
            # EM converges slowly: the same Ks with 4x the default iteration cap
            runs += [dict(_run_one(W, S, k, m, em_iter=settings.long_em_iter), auto=False)
                     for k in MODE_KS.get(name, ())]
        for r in runs:
            log.info("%s %s K=%d e3D %.4f (%.1f s)", name, r["method"], r["k"], r["e3d"], r["seconds"])
        result["sequences"][name] = {
            "frames": W.shape[0] // 2, "points": W.shape[1], "runs": runs,
            "curve": {"ks": curve.ks.tolist(), "relative": curve.relative.tolist(),
                      "chosen": curve.chosen, "rule": curve.rule}}
    for seed in settings.synthetic_seeds:
        W, S, _ = articulated_sequence(settings.synthetic_frames, np.random.default_rng(seed))
        for m in settings.methods:  # the same number of basis shapes for every method
            k = settings.synthetic_k - 1 if m in MEAN_PLUS_MODES else settings.synthetic_k
            r = _run_one(W, S, k, m)
            r["seed"] = seed
            result["synthetic"].append(r)
    result["load_after"] = os.getloadavg()
    atomic_write_json(out / "benchmarks.json", result)
    atomic_write_bytes(out / "benchmarks.md", _markdown(result, settings).encode())
    return result


def _markdown(result: dict, settings: NrsfmBenchSettings) -> str:
    lines = ["# Non-rigid SfM on the standard sequences", "",
             "e3D as defined in `shared/benchmarks/nrsfm/README.md` (normalised by s, rows centred, one "
             "orthogonal 3x3 with reflection over all frames, mean per-frame mean point distance). "
             "Times are wall-clock seconds on a shared 2-core machine "
             f"(load average {result['load_before'][0]:.1f} before, {result['load_after'][0]:.1f} after); "
             "compare them as ratios. *auto* marks the K chosen by the reprojection-curve rule, with "
             "method `dai`. `em-ppca` counts K as deformation modes beyond the mean shape, so it has "
             "K + 1 basis shapes (column *shapes*): em-ppca K = 12 is the same model size as dai K = 13.",
             ""]
    for name, seq in result["sequences"].items():
        lines += [f"## {name} ({seq['frames']} frames x {seq['points']} points)", ""]
        pub = PUBLISHED.get(name, [])
        if pub:
            lines += ["Published: " + "; ".join(f"{src}: **{e:.3f}** (K = {k})" for src, k, e in pub), ""]
        else:
            lines += ["No published e3D is given for this file in the benchmark README, and we found no "
                      "citable one: the tables of Akhter et al. 2008/2011, Dai et al. 2012/2014 and "
                      "Gotardo & Martinez 2011, which report on Torresani's shark, were not available to "
                      "us in readable form, so no published figure is claimed here.", ""]
        lines += ["| method | K | shapes | e3D | RMS reprojection (% of tracks) | time (s) |",
                  "|---|---|---|---|---|---|"]
        for r in seq["runs"]:
            k = f"{r['k']} (auto)" if r["auto"] else str(r["k"])
            lines.append(f"| {r.get('label', r['method'])} | {k} | {r['n_basis']} | {r['e3d']:.4f} | "
                         f"{100 * r['relative_reprojection']:.3g} "
                         f"| {r['seconds']:.2f} |")
        c = seq["curve"]
        lines += ["", f"Reprojection curve (`dai`, `{name}_curve.png`): K = {c['ks'][0]}..{c['ks'][-1]}, "
                  "relative RMS " + ", ".join(f"{100 * v:.3g}%" for v in c["relative"])
                  + f". Rule: {c['rule']}; chosen K = {c['chosen']}.", ""]
    if result["synthetic"]:
        lines += ["## Synthetic articulated sequences (not low-rank; camera orbiting at 5 deg/frame)", "",
                  f"{settings.synthetic_frames} frames, {settings.synthetic_k} basis shapes (K = "
                  f"{settings.synthetic_k}; em-ppca K = {settings.synthetic_k - 1} modes + mean), "
                  "`lipgen.nrsfm.synthetic.articulated_sequence(seed)`.", "",
                  "| seed | " + " | ".join(settings.methods) + " |",
                  "|---" * (len(settings.methods) + 1) + "|"]
        for seed in settings.synthetic_seeds:
            row = {r["method"]: r for r in result["synthetic"] if r["seed"] == seed}
            lines.append(f"| {seed} | " + " | ".join(
                f"{row[m]['e3d']:.4f} ({row[m]['seconds']:.1f} s)" for m in settings.methods) + " |")
        lines.append("")
    if any(r.get("label", r["method"]) != r["method"] for seq in result["sequences"].values()
           for r in seq["runs"]):
        lines += ["Rows labelled `(em_iter=N)` rerun em-ppca with N EM iterations instead of the default "
                  "cap: EM creeps, and its e3D keeps improving well past the default.", ""]
    return "\n".join(lines)
