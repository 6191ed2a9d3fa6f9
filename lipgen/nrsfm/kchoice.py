"""Choosing K without the truth: the reprojection curve (Bregler et al. Fig 2) and, for ``dai`` and
``dai-ba``, the smoothest rotations.

Dai's trace-norm shapes depend on K only through the rotations (the rank-3K factor and its
corrective triple), and a K too small or too large for the sequence shows first in them: too
small, and no corrective triple makes every frame orthonormal, so the rotations bend to fit;
too large for the frames, and the triple fits noise and the rotations jitter. Both leave the
reprojection error at zero (the trace-norm shapes reproject exactly), so the reprojection curve
cannot see them. :func:`smooth_k` picks the K whose rotations are smoothest in time
(:func:`lipgen.nrsfm.plausibility.rotation_roughness`) - and among the smoothest, the smallest K
that explains the tracks exactly with K shapes (noise-free low-rank data), if one does.

The rule and its tolerance were chosen on the validation bodies of seeds 100-107
(:mod:`lipgen.nrsfm.validation`, 80 and 300 frames), never on drink, jaws or their truth, then
checked on fresh seeds 300-308; one of them (walk-304, 80 frames) showed that an exact fit must
also have smooth rotations, so that sequence is no longer held out (``lipgen experiment nrsfm``
reports both sets).
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from lipgen._threads import single_threaded
from lipgen.nrsfm._tracks import check_tracks
from lipgen.nrsfm.consensus import (
    CONSENSUS_KS,
    ERROR_CORRELATION,
    check_rho,
    check_roughness_ratio,
    consensus_reconstruction,
)
from lipgen.nrsfm.engine import at_unit_scale, reconstruct_k
from lipgen.nrsfm.kscan import DaiScan, scan_estimated, scan_smooth
from lipgen.nrsfm.plausibility import rotation_roughness
from lipgen.nrsfm.record import MEAN_PLUS_MODES, Reconstruction, check_method_k
from lipgen.nrsfm.reliability import shrink_depth, split_half_reliability
from lipgen.nrsfm.support import SUPPORT_DEG, depth_support, flat_answer

__all__ = ["curve_values", "choose_k", "smooth_k", "candidate_ks", "reconstruct_auto", "SMOOTH_TOL",
           "SMOOTH_METHODS", "shrink_unreliable_depth"]

log = logging.getLogger(__name__)

SMOOTH_TOL = 0.05
""":func:`smooth_k` takes the smallest K whose rotation roughness is within this fraction of the
smoothest K's (chosen on the validation seeds 100-107: 0.0, 0.05 and 0.3 all kept every sequence
below the flat baseline; 0.05 prefers fewer basis shapes when the rotations hardly differ)."""

SMOOTH_METHODS = frozenset({"dai", "dai-ba"})
"""Methods whose ``k="auto"`` uses :func:`smooth_k`; the others use the reprojection curve."""


def candidate_ks(F: int, P: int, n_observed: int, method: str, kmax: int = 15) -> list[int]:
    """The Ks that ``method`` accepts on tracks of F frames, P points and ``n_observed`` sightings,
    1 (0 for em-ppca) up to ``kmax`` (the ones :func:`check_method_k` refuses are left out)."""
    first = 0 if method in MEAN_PLUS_MODES else 1
    ks = []
    for k in range(first, kmax + 1):
        try:
            ks.append(check_method_k(k, method, F, P, n_observed))
        except ValueError:
            break
    return ks


def smooth_k(candidates: list[Reconstruction], tol: float = SMOOTH_TOL) -> tuple[int, dict]:
    """Pick K among reconstructions of one sequence at several K.

    Rule: among the Ks whose rotation roughness is at most ``1 + tol`` times the least, the
    smallest K whose shapes are an exact K-shape fit (``info["shapes"] == "rank-K fit"``: tracks
    of numerical rank <= 3K explained exactly), if any; else the smallest of them. (An exact fit
    with rough rotations is overfitting: on a fresh 80-frame body, 13 shapes fitted exactly with
    jittering rotations gave e3D 0.64 against the flat baseline's 0.46.)

    Parameters
    ----------
    candidates : list of Reconstruction
        One per K, all of the same tracks.
    tol : float

    Returns
    -------
    k : int
    record : dict
        ``ks``, ``rotation_roughness``, ``exact`` (lists per K), ``chosen``, ``rule``.
    """
    if not candidates:
        raise ValueError("smooth_k needs at least one reconstruction")
    ks = [int(r.k) for r in candidates]
    rough = [rotation_roughness(r.rotations) for r in candidates]
    exact = [r.info.get("shapes") == "rank-K fit" for r in candidates]
    least = min(rough)
    smooth = [i for i, v in enumerate(rough) if v <= (1 + tol) * least]
    exact_smooth = [ks[i] for i in smooth if exact[i]]
    chosen = min(exact_smooth) if exact_smooth else min(ks[i] for i in smooth)
    rule = (f"among the Ks whose rotation roughness is within {tol:g} of the least (the smoothest "
            "rotations), the smallest K fitted exactly by K shapes, else the smallest K")
    return chosen, {"ks": ks, "rotation_roughness": rough, "exact": exact, "chosen": chosen, "rule": rule}


@single_threaded(always=True)
@at_unit_scale
def reconstruct_auto(W, method: str, visible=None, *, kmax: int = 15, consensus: int = CONSENSUS_KS,
                     support: float | None = SUPPORT_DEG, rho: float = ERROR_CORRELATION,
                     roughness_ratio: float | None = None, **options) -> Reconstruction:
    """:func:`lipgen.nrsfm.reconstruct` with ``k="auto"``.

    ``dai`` and ``dai-ba``: ``dai`` at every K of :func:`candidate_ks`, K by :func:`smooth_k`
    (kept in ``info["k_choice"]``): the rotations at every K, the shapes only at the Ks the choice
    can need (:func:`lipgen.nrsfm.kscan.scan_smooth`; the exhaustive search's answer, bit for bit). With
    points missing, the Ks to finish are found from estimates (:func:`lipgen.nrsfm.kscan.scan_estimated`:
    a completion stopped after a few steps at every K, the full one only at the Ks used).
    ``dai`` then replaces the chosen K's depth by the consensus of the ``consensus`` smoothest Ks,
    shrunk by the James-Stein factor of their disagreement
    (:func:`lipgen.nrsfm.consensus.consensus_reconstruction`, kept in ``info["depth_consensus"]``;
    an exact K-shape fit is kept as it is), and returns the flat answer (zero depth) when the even and
    the odd frames alone give rotations that disagree by more than ``support`` degrees
    (:func:`lipgen.nrsfm.support.depth_support`; kept in ``info["depth_support"]``, read by
    ``Reconstruction.depth_supported``). ``dai-ba``'s refinement runs at the chosen K, without the
    consensus or the test. The split-half shrinkage (:func:`shrink_unreliable_depth`) stays opt-in: on fresh
    bodies (seeds 800-819, 80 frames) it helped 5 and hurt 6. Other
    methods: K from the reprojection curve (:func:`curve_values`, :func:`choose_k`; kept in
    ``info["k_curve"]``).

    Parameters
    ----------
    W : (2F, P) array_like
    method : str
    visible : (F, P) array_like of bool, optional
    kmax : int
        Largest K tried.
    consensus : int
        ``dai``: number of the smoothest Ks whose depths are averaged (1: the chosen K's depth as it is).
    support : float or None
        ``dai``: the largest disagreement (degrees) of the halves' rotations for which the depth is
        kept (default :data:`lipgen.nrsfm.support.SUPPORT_DEG`); None: no test.
    rho : float
        ``dai``: assumed correlation of those Ks' depth errors, which sets the James-Stein factor's noise
        (:func:`lipgen.nrsfm.consensus.design_effect`; default
        :data:`lipgen.nrsfm.consensus.ERROR_CORRELATION`).
    roughness_ratio : float, optional
        ``dai``: only Ks whose rotation roughness is at most this multiple of the least join the
        consensus (:func:`lipgen.nrsfm.consensus.consensus_depth`). Default None (off): 5 left no
        held-out sequence worse than flat (main: 2 of 40 lip views) but raised the lip views' mean
        e3D, which its pre-registered rule forbade (``renders/examples/nrsfm/lips_consensus_19l.md``);
        on a second fresh set it left 5 of 60 worse than flat against main's 4
        (``renders/examples/nrsfm/flat29.md``).
    **options
        As :func:`lipgen.nrsfm.reconstruct`.

    Returns
    -------
    Reconstruction
    """
    check_rho(rho)  # before any work, on every path (they are used by dai's consensus only)
    check_roughness_ratio(roughness_ratio)
    if method not in SMOOTH_METHODS:
        ks, _, relative = curve_values(W, None, method, visible, **options)
        chosen, rule = choose_k(ks, relative)
        rec = reconstruct_k(W, chosen, method, visible, **options)
        rec.info["k_curve"] = {"ks": ks.tolist(), "relative": relative.tolist(), "chosen": chosen,
                               "rule": rule}
        return rec
    tracks = check_tracks(W, visible)
    F, P = tracks.mask.shape
    ks = candidate_ks(F, P, tracks.n_observed, method, kmax)
    if not ks:  # no K fits: let the engine give its message for K = 1
        return reconstruct_k(W, 1, method, visible, **options)
    scan = DaiScan(W, visible, **options)
    # with points missing, estimates guide the scan (the full completion at every K cost 7-8x the
    # complete tracks' time on drink); complete tracks: bounds, the exhaustive search's answer
    scanner = scan_smooth if tracks.complete else scan_estimated
    runs, bounds = scanner(scan, ks, SMOOTH_TOL, consensus if method == "dai" else 1)
    chosen, record = smooth_k(runs)
    record = _whole_record(record, ks, bounds) | {"unfinished": "bound" if tracks.complete else "estimate"}
    log.info("k='auto': K = %d (%s)", chosen, record["rule"])
    if method == "dai":
        rec = consensus_reconstruction(runs, [int(r.k) for r in runs].index(chosen), consensus, rho,
                                       roughness_ratio)
        if support is not None:
            rec = _supported(scan, rec, chosen, support)
    else:
        rec = reconstruct_k(W, chosen, method, visible, **options)
    rec.info["k_choice"] = record
    return rec


def _supported(scan: DaiScan, rec: Reconstruction, k: int, threshold: float) -> Reconstruction:
    """``rec`` with ``info["depth_support"]`` (the same arrays) when the halves' rotations agree at K,
    else the flat answer (:func:`lipgen.nrsfm.support.flat_answer`). An exact K-shape fit is not tested
    (the tracks are explained exactly, and its frames need not follow each other in time)."""
    if rec.info.get("shapes") == "rank-K fit":
        record = {"supported": True, "tested": False, "angle_deg": float("nan"), "k": None,
                  "reason": "exact K-shape fit: not tested, depth kept"}
        return replace(rec, info=rec.info | {"depth_support": record})
    supported, record = depth_support(scan.W, k, scan.visible, threshold=threshold,
                                      seed=scan.options.get("seed", 0),
                                      n_starts=scan.options.get("n_starts", 4),
                                      first_stage=scan.first_stage(k))
    if supported:
        return replace(rec, info=rec.info | {"depth_support": record})   # the same arrays, bit for bit
    log.warning("k='auto': depth not supported by the tracks (%s); returning the flat answer (zero depth)",
                record["reason"])
    return flat_answer(rec, record)


def _whole_record(record: dict, ks: list[int], bounds: dict) -> dict:
    """:func:`smooth_k`'s record over the finished Ks, widened to every candidate K: an unfinished K
    gets its roughness bound (with points missing: its last estimate, see ``unfinished``) and ``exact``
    False (``finished`` says which is which)."""
    done = dict(zip(record["ks"], zip(record["rotation_roughness"], record["exact"], strict=True),
                    strict=True))
    rough = [done[k][0] if k in done else bounds[k] for k in ks]
    return record | {"ks": list(ks), "rotation_roughness": rough,
                     "exact": [bool(done[k][1]) if k in done else False for k in ks],
                     "finished": [k in done for k in ks]}


def shrink_unreliable_depth(W, rec: Reconstruction, visible=None, **options) -> Reconstruction:
    """An opt-in last step of ``k="auto"`` for ``dai`` and ``dai-ba``: ``rec``'s depth times its split-half
    reliability (:func:`lipgen.nrsfm.reliability.split_half_reliability` at ``rec.k``), so that depth
    the even and the odd frames do not reproduce moves towards the flat answer.

    Parameters
    ----------
    W : (2F, P) array_like
        The tracks ``rec`` was reconstructed from.
    rec : Reconstruction
    visible : (F, P) array_like of bool, optional
    **options
        As :func:`lipgen.nrsfm.reconstruct`.

    Returns
    -------
    Reconstruction
        With ``info["depth_reliability"]`` (``rho``, the halves' ``k``, ``reason``) and, when shrunk,
        ``info["depth_factor"]``. An exact K-shape fit (``info["shapes"] == "rank-K fit"``) is returned
        as it is, with ``rho`` 1.
    """
    if rec.info.get("shapes") == "rank-K fit":
        # tracks explained exactly by K shapes (noise-free low-rank data) need no neighbouring frames
        # to agree: such frames may be unrelated in time, which the halves' comparison assumes
        rec.info["depth_reliability"] = {"rho": 1.0, "k": None, "reason": "exact K-shape fit: depth kept"}
        return rec
    rho, reliability = split_half_reliability(W, int(rec.k), visible, **options)
    out = shrink_depth(rec, rho)
    out.info["depth_reliability"] = reliability
    return out


@single_threaded(always=True)
def curve_values(W, ks, method: str, visible, progress: bool = False, **options):
    """The reprojection curve's values: ks (n,) int, RMS (n,) and RMS relative to the centred tracks
    (see :func:`lipgen.nrsfm.reprojection_curve`, which adds the choice of K)."""
    tracks = check_tracks(W, visible)
    F, P = tracks.mask.shape
    if ks is None:
        limit = min(2 * F, P - 1) // 3
        ks = range(1, min(limit, 15) + 1)
        if method in MEAN_PLUS_MODES:
            ks = [k - 1 for k in ks]
    ks = np.array([check_method_k(int(k), method, F, P, tracks.n_observed) for k in ks])
    if ks.size == 0:
        raise ValueError("ks is empty: give at least one K")
    seen = np.repeat(tracks.mask, 2, axis=0)
    means = (tracks.W * seen).sum(1) / seen.sum(1)
    scale = float(np.sqrt((((tracks.W - means[:, None]) * seen) ** 2).sum() / seen.sum()))
    rms = []
    iterator = ks
    if progress:
        from tqdm import tqdm

        iterator = tqdm(ks, desc=f"reprojection curve ({method})", unit="K")
    for k in iterator:
        rec = reconstruct_k(tracks.W, int(k), method, None if tracks.complete else tracks.mask, **options)
        # methods that return more than K shapes (dai's trace-norm shapes) report K shapes' fit apart
        rms.append(rec.info.get("rank_k_reprojection_rms", rec.reprojection_rms))
        log.info("K=%d: RMS reprojection %.4g (%.3g%%)", k, rms[-1], 100 * rms[-1] / scale)
    rms = np.array(rms)
    return ks, rms, rms / scale


def choose_k(ks, relative, rtol: float = 0.01, flat: float = 0.05) -> tuple[int, str]:
    """Pick K from a reprojection curve.

    Rule: the smallest K whose relative RMS reprojection error is at most ``rtol``; if no K
    reaches it, the smallest K after which one more basis shape lowers the error by less than
    ``flat`` of its value (the curve has reached its floor: Bregler's "the error vanishes");
    otherwise the largest K tried.

    Returns
    -------
    k : int
    rule : str
    """
    ks = np.asarray(ks, dtype=int)
    rel = np.asarray(relative, dtype=float)
    order = np.argsort(ks)
    ks, rel = ks[order], rel[order]
    rule = (f"smallest K with RMS reprojection <= {rtol:g} of the RMS of the centred tracks; else the "
            f"first K after which one more basis lowers it by < {flat:g} of its value; else the largest K")
    hit = np.flatnonzero(rel <= rtol)
    if hit.size:
        return int(ks[hit[0]]), rule
    for i in range(len(ks) - 1):
        if rel[i + 1] > (1 - flat) * rel[i]:
            return int(ks[i]), rule
    return int(ks[-1]), rule
