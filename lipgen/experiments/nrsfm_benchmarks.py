"""NRSfM on the standard sequences (drink, jaws) beside the published figures and the flat
(zero-depth) baseline, and on the held-out validation set of synthetic human bodies
(:mod:`lipgen.nrsfm.validation`): e3D, reprojection, CPU and wall time. Writes ``benchmarks.md``,
``benchmarks.json`` and the reprojection curves."""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lipgen._io import atomic_write_bytes, atomic_write_json
from lipgen._threads import single_threaded
from lipgen.experiments.nrsfm_report import PUBLISHED, markdown

__all__ = ["DEFAULT_DATA", "PUBLISHED", "NrsfmBenchSettings", "run_nrsfm_benchmarks", "data_dir",
           "hide_points"]

log = logging.getLogger(__name__)

DEFAULT_DATA = "benchmarks/nrsfm"
"""Where the benchmark sequences live unless ``LIPGEN_NRSFM_DATA`` says otherwise: relative to the
source tree's root (no machine's own path ships in the package)."""

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
    """``$LIPGEN_NRSFM_DATA``, else :data:`DEFAULT_DATA` under the source tree's root, else the
    project's shared ``benchmarks/nrsfm`` beside the source tree (where this project keeps them)."""
    env = os.environ.get("LIPGEN_NRSFM_DATA")
    if env:
        return Path(env)
    root = Path(__file__).resolve().parents[2]
    inside, beside = root / DEFAULT_DATA, root.parent / "shared" / DEFAULT_DATA
    return beside if not inside.is_dir() and beside.is_dir() else inside


@dataclass(frozen=True)
class NrsfmBenchSettings:
    """What ``lipgen experiment nrsfm`` runs: methods, sequences and basis sizes.

    The defaults take minutes: two development bodies (walk, pickup) at 80 frames and the held-out
    check on fresh seeds 1400-1419 at 80 frames (``dai``'s automatic K finds the rotations at
    K = 1..15 and the shapes at a few, about 25-40 s of CPU on an 80-frame body under load).
    :meth:`full` is the complete run (eight
    development bodies at 300 frames; seeds 300-310 and 400-410 at 300 and 80 frames; em-ppca
    also with 2000 EM iterations on drink and jaws), about an hour of CPU.
    """
    methods: tuple[str, ...] = ("bregler", "dai", "dai-ba", "em-ppca")
    sequences: tuple[str, ...] = ("drink", "jaws")
    validation_seeds: tuple[int, ...] = (100, 101)
    validation_ks: tuple[int, ...] = (4, 8)
    validation_frames: int = 80
    check_seeds: tuple[int, ...] = tuple(range(1400, 1420))
    mocap_clips: tuple[str, ...] = ("run0901", "walk0701", "basket0603", "soccer1006", "s16t57", "s20t06")
    check_frames: tuple[int, ...] = (80,)
    kmax: int = 13
    rtol: float = 0.01
    long_em_iter: int | None = None

    @classmethod
    def full(cls, **changes) -> NrsfmBenchSettings:
        """The complete run: seeds 100-107 at 300 frames, fresh seeds 300-310 and 400-410 at 300 and 80."""
        return cls(**({"validation_seeds": tuple(range(100, 108)), "validation_frames": 300,
                       "check_seeds": (*range(300, 311), *range(400, 411)), "check_frames": (300, 80),
                       "long_em_iter": 2000}
                      | changes))


class _DaiRuns:
    """``dai`` on one sequence at each K, run once and shared by the reprojection curve, the fixed Ks
    and the chosen K's own depth beside the automatic K's."""

    def __init__(self, W):
        self.W = W
        self.runs: dict[int, tuple] = {}

    def get(self, k: int):
        """``(Reconstruction, wall seconds, CPU seconds)`` of ``dai`` at K."""
        from lipgen.nrsfm import reconstruct

        if k not in self.runs:
            t0, c0 = time.perf_counter(), time.process_time()
            rec = reconstruct(self.W, k, method="dai")
            self.runs[k] = (rec, time.perf_counter() - t0, time.process_time() - c0)
        return self.runs[k]


def _load(name: str):
    path = data_dir() / f"{name}.npz"
    if not path.is_file():
        return None
    with np.load(path, allow_pickle=False) as d:
        return d["W"], d["S"]


def flat_e3d(W, S) -> float:
    """e3D of the flat baseline, the tracks with zero depth (:func:`lipgen.nrsfm.metrics.flat_e3d`)."""
    from ..nrsfm.metrics import flat_e3d as flat

    return flat(W, S)


def _record(rec, W, S, seconds: float, cpu: float, label: str) -> dict:
    from lipgen.nrsfm import e3d, n_basis_shapes

    k = int(rec.k)
    return {"method": rec.method, "label": label, "k": k, "n_basis": n_basis_shapes(k, rec.method),
            "e3d": e3d(S_est=rec.S, S_true=S), "seconds": seconds, "cpu_seconds": cpu,
            "shapes": rec.info.get("shapes", ""), "ba_kept": rec.info.get("ba_kept"),
            "reprojection_rms": rec.reprojection_rms,
            "relative_reprojection": rec.reprojection_rms / float(np.sqrt(np.mean(
                (W - W.mean(1, keepdims=True)) ** 2)))}


def _run_one(W, S, k, method, cache: _DaiRuns | None = None, **options) -> dict:
    """One reconstruction scored; ``dai`` at a fixed K takes ``cache``'s run, ``dai`` and ``dai-ba`` at
    K = "auto" are timed as called, and report beside the chosen K's own depth from ``cache``."""
    from lipgen.nrsfm import reconstruct

    label = method + "".join(f" ({key}={value})" for key, value in options.items())
    if cache is not None and not options and method in ("dai", "dai-ba"):
        if k == "auto":  # timed as a user calls it (it finishes dai only where its choice needs it)
            t0, c0 = time.perf_counter(), time.process_time()
            rec = reconstruct(W, "auto", method=method)
            out = _record(rec, W, S, time.perf_counter() - t0, time.process_time() - c0, label)
            single = cache.get(int(rec.k))[0]
            # the chosen K's own depth, reported beside
            out["e3d_single"] = _record(single, W, S, 0.0, 0.0, label)["e3d"]
            out["consensus_factor"] = rec.info.get("depth_consensus", {}).get("factor", 1.0)
            support = rec.info.get("depth_support", {})
            out["depth_supported"] = rec.depth_supported
            out["support_angle"] = support.get("angle_deg", float("nan"))
            if not rec.depth_supported:   # the answer the test replaced by the flat one, reported beside
                from lipgen.nrsfm.kchoice import reconstruct_auto

                kept = reconstruct_auto(W, method, support=None)
                out["e3d_unsupported"] = _record(kept, W, S, 0.0, 0.0, label)["e3d"]
            return out
        if method == "dai":
            rec, seconds, cpu = cache.get(int(k))
            return _record(rec, W, S, seconds, cpu, label)
    t0, c0 = time.perf_counter(), time.process_time()
    rec = reconstruct(W, k, method=method, **options)
    return _record(rec, W, S, time.perf_counter() - t0, time.process_time() - c0, label)


def hide_points(F: int, P: int, kind: str, fraction: float = 0.1, seed: int = 0) -> np.ndarray:
    """A visibility mask hiding about ``fraction`` of the points.

    Parameters
    ----------
    F, P : int
        Frames and points.
    kind : {"random", "gaps"}
        Each point of each frame hidden independently, or runs of 20-60 frames of one point hidden
        until the fraction is reached.
    fraction : float
    seed : int

    Returns
    -------
    (F, P) bool
        True where a point is seen.
    """
    rng = np.random.default_rng(seed)
    if kind == "random":
        return rng.random((F, P)) > fraction
    visible = np.ones((F, P), dtype=bool)
    while (~visible).mean() < fraction:
        length = int(rng.integers(20, min(60, F)))
        start = int(rng.integers(0, F - length + 1))
        visible[start:start + length, int(rng.integers(P))] = False
    return visible


def _missing_runs(settings: NrsfmBenchSettings) -> list[dict]:
    """``dai`` on drink at K = 12 with every point seen, and with 10 % hidden at random and in gaps."""
    data = _load("drink") if "drink" in settings.sequences and "dai" in settings.methods else None
    if data is None:
        return []
    W, S = data
    F, P = W.shape[0] // 2, W.shape[1]
    runs = []
    for kind in ("none", "random", "gaps"):
        visible = None if kind == "none" else hide_points(F, P, kind)
        Wv = W if visible is None else np.where(np.repeat(visible, 2, axis=0), W, np.nan)
        r = _run_one(Wv, S, 12, "dai", visible=visible) if visible is not None else _run_one(W, S, 12, "dai")
        runs.append(dict(r, hidden=kind, fraction=0.0 if visible is None else float((~visible).mean())))
    return runs


def _curve(cache: _DaiRuns, ks, rtol: float):
    """The reprojection curve of ``dai`` (:func:`lipgen.nrsfm.reprojection_curve`) from the cached runs."""
    from lipgen.nrsfm import KCurve, choose_k

    W = cache.W
    scale = float(np.sqrt(np.mean((W - W.mean(1, keepdims=True)) ** 2)))
    ks = np.array(list(ks))
    recs = [cache.get(int(k))[0] for k in ks]
    rms = np.array([r.info.get("rank_k_reprojection_rms", r.reprojection_rms) for r in recs])
    chosen, rule = choose_k(ks, rms / scale, rtol=rtol)
    return KCurve(ks=ks, rms=rms, relative=rms / scale, chosen=chosen, rule=rule, method="dai")


def _score_sequence(seq, settings: NrsfmBenchSettings) -> dict:
    """Every method of ``settings`` on one filmed sequence, at the validation Ks and at its own K, and
    the flat baseline."""
    from lipgen.nrsfm import MEAN_PLUS_MODES

    cache = _DaiRuns(seq.W)
    entry = {"name": seq.name, "points": seq.W.shape[1], "frames": seq.W.shape[0] // 2,
             "degrees_per_frame": seq.degrees_per_frame, "flat_e3d": flat_e3d(seq.W, seq.S), "runs": []}
    for m in settings.methods:  # each K as the number of basis shapes (em-ppca: K - 1 modes + mean)
        for k in (*settings.validation_ks, "auto"):
            kk = k - 1 if (m in MEAN_PLUS_MODES and k != "auto") else k
            r = _run_one(seq.W, seq.S, kk, m, cache)
            r["auto"] = k == "auto"
            entry["runs"].append(r)
            log.info("%s %s K=%s e3D %.4f (flat %.4f)", seq.name, m, r["k"], r["e3d"], entry["flat_e3d"])
    return entry


@single_threaded  # tracks of tens of points: BLAS threads only wait (lipgen._threads)
def run_nrsfm_benchmarks(out, settings: NrsfmBenchSettings = NrsfmBenchSettings()) -> dict:
    """Run everything, write the report into folder ``out``, return the figures."""
    from lipgen.nrsfm import MEAN_PLUS_MODES, plot_curve
    from lipgen.nrsfm.kchoice import SMOOTH_METHODS
    from lipgen.nrsfm.validation import human_sequence

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    result = {"load_before": os.getloadavg(), "sequences": {}, "validation": [],
              "settings": settings.__dict__, "data": str(data_dir())}
    for name in settings.sequences:
        data = _load(name)
        if data is None:
            log.warning("no %s.npz under %s; skipped", name, data_dir())
            continue
        W, S = data
        cache = _DaiRuns(W)
        curve = _curve(cache, range(1, settings.kmax + 1), settings.rtol)
        plot_curve(curve, out / f"{name}_curve.png")
        ks = sorted(set(SEQUENCE_KS.get(name, ())) | {curve.chosen})
        runs = [_run_one(W, S, k, m, cache) for k in ks for m in settings.methods if m not in MEAN_PLUS_MODES]
        for r in runs:
            r["auto"] = r["k"] == curve.chosen and r["method"] not in SMOOTH_METHODS
        # dai and dai-ba choose their own K by the smoothest rotations (lipgen.nrsfm.kchoice)
        runs += [dict(_run_one(W, S, "auto", m, cache), auto=True) for m in settings.methods
                 if m in SMOOTH_METHODS]
        for m in (m for m in settings.methods if m in MEAN_PLUS_MODES):
            runs += [dict(_run_one(W, S, k, m), auto=False) for k in MODE_KS.get(name, ())]
            if settings.long_em_iter:  # EM converges slowly: the same Ks with a larger iteration cap
                runs += [dict(_run_one(W, S, k, m, em_iter=settings.long_em_iter), auto=False)
                         for k in MODE_KS.get(name, ())]
        for r in runs:
            log.info("%s %s K=%d e3D %.4f (%.1f s)", name, r["method"], r["k"], r["e3d"], r["seconds"])
        result["sequences"][name] = {
            "frames": W.shape[0] // 2, "points": W.shape[1], "runs": runs, "flat_e3d": flat_e3d(W, S),
            "curve": {"ks": curve.ks.tolist(), "relative": curve.relative.tolist(),
                      "chosen": curve.chosen, "rule": curve.rule}}
    result["missing"] = _missing_runs(settings)
    for seed in settings.validation_seeds:
        body = human_sequence(seed, settings.validation_frames)
        result["validation"].append(_score_sequence(body, settings))
    # public motion capture, held out: every method at the validation Ks and its own
    if settings.mocap_clips:
        from lipgen.nrsfm.mocap import mocap_set

        result["mocap"] = [_score_sequence(seq, settings) for seq in mocap_set(clips=settings.mocap_clips)]
    # fresh seeds, never looked at while choosing the rule: dai's automatic K against the flat baseline
    result["check"] = []
    for seed in settings.check_seeds:
        for frames in settings.check_frames:
            seq = human_sequence(seed, frames)
            r = _run_one(seq.W, seq.S, "auto", "dai", _DaiRuns(seq.W))
            result["check"].append({"name": f"{seq.name} ({frames} frames)", "seed": seed,
                                    "flat_e3d": flat_e3d(seq.W, seq.S), "k": r["k"], "e3d": r["e3d"],
                                    "e3d_single": r["e3d_single"], "consensus_factor": r["consensus_factor"],
                                    "cpu_seconds": r["cpu_seconds"], "depth_supported": r["depth_supported"],
                                    "support_angle": r["support_angle"],
                                    "e3d_unsupported": r.get("e3d_unsupported")})
            log.info("check %s: dai K=auto (%d) e3D %.4f, flat %.4f", result["check"][-1]["name"], r["k"],
                     r["e3d"], result["check"][-1]["flat_e3d"])
    result["load_after"] = os.getloadavg()
    atomic_write_json(out / "benchmarks.json", result)
    atomic_write_bytes(out / "benchmarks.md", markdown(result, settings).encode())
    return result
