"""The engine of :func:`lipgen.nrsfm.reconstruct` at one given K: scale, rotations, shapes, refinement."""

from __future__ import annotations

import functools
import inspect
import logging

import numpy as np

from lipgen.nrsfm._rotation import corrective_triple, orient_frames, rotations_from_triple
from lipgen.nrsfm._tracks import check_tracks, complete_tracks, factor, numerical_rank
from lipgen.nrsfm.bmm import min_trace_norm_shapes, rank_k_shapes
from lipgen.nrsfm.bregler import bregler_factorization
from lipgen.nrsfm.empnd import pnd_reconstruction
from lipgen.nrsfm.emppca import em_ppca
from lipgen.nrsfm.keep import keep_refinement
from lipgen.nrsfm.lowrank import fit_rank_k
from lipgen.nrsfm.plausibility import shape_figures
from lipgen.nrsfm.record import Reconstruction, check_method_k
from lipgen.nrsfm.refine import bundle_adjust

__all__ = ["reconstruct_k", "at_unit_scale"]

log = logging.getLogger(__name__)


def reconstruct_k(W, k: int, method: str, visible=None, *, seed: int = 0, n_starts: int = 4,
                  shape_starts: int = 8, refine_iter: int = 100, em_iter: int = 500) -> Reconstruction:
    """:func:`lipgen.nrsfm.reconstruct` at a given integer K (the caller limits the BLAS threads).

    Parameters
    ----------
    W : (2F, P) array_like
    k : int
    method : str
    visible : (F, P) array_like of bool, optional
    seed, n_starts, shape_starts, refine_iter, em_iter
        As :func:`lipgen.nrsfm.reconstruct`.

    Returns
    -------
    Reconstruction
    """
    options = {"seed": seed, "n_starts": n_starts, "shape_starts": shape_starts, "refine_iter": refine_iter,
               "em_iter": em_iter}
    W, unit = _normalise_scale(W, visible)
    return _scale_back(_reconstruct(W, k, method, visible, **options), unit)


def at_unit_scale(solve):
    """Decorate a solver ``solve(W, ..., visible=None, ...) -> Reconstruction`` so that W whose largest
    magnitude lies outside [2**-20, 2**20] is divided by a power of two near it (:func:`_normalise_scale`)
    and the answer scaled back, as :func:`reconstruct_k` does: the K choice of ``k="auto"`` then solves
    any scale alike (W x 1e-300 was refused as constant, W x 1e300 overflowed). Tracks of ordinary
    magnitude (normalised, mm, pixels) are passed as they are, so their answers are unchanged."""
    signature = inspect.signature(solve)

    @functools.wraps(solve)
    def solve_at_unit_scale(*args, **kwargs):
        bound = signature.bind(*args, **kwargs)
        W, unit = _normalise_scale(bound.arguments["W"], bound.arguments.get("visible"))
        if 2.0**-20 <= unit <= 2.0**20:
            return solve(*args, **kwargs)
        bound.arguments["W"] = W
        return _scale_back(solve(*bound.args, **bound.kwargs), unit)
    return solve_at_unit_scale


def _scale_back(rec: Reconstruction, unit: float) -> Reconstruction:
    """``rec`` of tracks divided by ``unit`` (:func:`_normalise_scale`) in the tracks' own units."""
    if unit == 1.0:
        return rec
    info = rec.info | {"scale": unit}
    # figures in track units scale back too (the curve of K compares them with the tracks' own RMS)
    if "rank_k_reprojection_rms" in info:
        info["rank_k_reprojection_rms"] *= unit
    if "ba_cost" in info:
        info["ba_cost"] = [c * unit**2 for c in info["ba_cost"]]
    return Reconstruction(rotations=rec.rotations, weights=rec.weights, basis=rec.basis * unit,
                          translation=rec.translation * unit, method=rec.method, k=rec.k,
                          reprojection_rms=rec.reprojection_rms * unit, info=info)


def _reprojection_rms(tracks, R, C, B, t) -> float:
    pred = (R @ np.einsum("fk,kip->fip", C, B))[:, :2] + t[:, :, None]
    F, P = tracks.mask.shape
    res = (tracks.W.reshape(F, 2, P) - pred) * tracks.mask[:, None, :]
    return float(np.sqrt((res**2).sum() / (2 * tracks.n_observed)))


def _as_basis(shapes: np.ndarray, rtol: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """Shapes (F, 3, P) as weights (F, r) and basis (r, 3, P), r their numerical rank (exact)."""
    F, _, P = shapes.shape
    U, s, Vt = np.linalg.svd(shapes.reshape(F, -1), full_matrices=False)
    r = max(int((s > rtol * s[0]).sum()), 1)
    return U[:, :r] * s[:r], Vt[:r].reshape(r, 3, P)


def _tidy(R, C, B, t):
    """Orient the frames (per-frame sign, see :func:`orient_frames`) and centre the basis shapes,
    moving their mean into the image translations."""
    R, _, sign = orient_frames(R, np.einsum("fk,kip->fip", C, B))
    C = C * sign[:, None]
    centre = B.mean(axis=2)                                    # (K, 3)
    t = t + np.einsum("fia,fa->fi", R[:, :2], C @ centre)
    return R, C, B - centre[:, :, None], t


_EXACT_COMPLETION = 1e-6
"""Relative misfit of the rank-3K completion below which incomplete tracks may be exactly K shapes
(exact low-rank tracks complete to a misfit of ~1e-15; drink with 10 % hidden, K = 12, to 3e-5)."""

_TINY = float(np.finfo(np.float64).tiny) * 2.0**20
"""Below this largest magnitude, coordinates a millionth of it would be subnormal (lost digits)."""


def _normalise_scale(W, visible):
    """W divided by a power of two near its largest observed magnitude (an exact rescale: the
    result scales back without rounding), and that power. Nothing is checked here beyond what
    the scale needs; :func:`check_tracks` does the rest."""
    from .._validate import as_float_array

    W = as_float_array(W, "W", finite=False)
    if W.ndim != 2:
        return W, 1.0
    seen = np.isfinite(W)
    if visible is not None and np.shape(visible) == (W.shape[0] // 2, W.shape[1]) and W.shape[0] % 2 == 0:
        seen &= np.repeat(np.asarray(visible, dtype=bool), 2, axis=0)
    if not seen.any():
        return W, 1.0
    top = float(np.abs(W[seen]).max())
    if top == 0.0:
        return W, 1.0
    if top < _TINY:
        raise ValueError(f"W of shape {W.shape} has coordinates no larger than {top:.3g}: at this scale "
                         f"(below {_TINY:.3g}) doubles turn subnormal and lose digits; multiply W by a "
                         "large power of ten (the shapes scale with it)")
    unit = float(2.0 ** np.round(np.log2(top)))
    return W / unit, unit


def _centred(tracks, k: int, completion_steps: int = 100, completion=None, start=None):
    """Completed tracks centred per frame (2F, P), their translations (F, 2), and the record
    (``completion_steps``: the completion's cap on steps; ``completion``: a
    :class:`lipgen.nrsfm.completion.SubspaceCompletion` of these tracks at rank 3K to go on with;
    ``start``: complete rows over the same points for a new completion to start from)."""
    F = tracks.n_frames
    full, misfit = complete_tracks(tracks, 3 * k, max_iter=completion_steps, return_residual=True,
                                   resume=completion, start=start)
    t = full.mean(axis=1)
    Wc = full - t[:, None]
    rank, sv = numerical_rank(Wc)
    if rank < 3:
        raise ValueError(f"the centred (completed) tracks have numerical rank {rank} < 3 (singular values "
                         f"{np.array2string(sv[:4], precision=3)}): not even a rigid structure is defined")
    if rank < 3 * k:
        log.info("tracks have numerical rank %d < 3K = %d (degenerate basis shapes); the factor keeps "
                 "rank %d", rank, 3 * k, rank)
    info: dict = {"rank": rank, "singular_values": sv[: 3 * k + 1].tolist(), "completion_misfit": misfit}
    return Wc, t.reshape(F, 2), info


def _bregler(tracks, k: int):
    Wc, t, info = _centred(tracks, k)
    R, C, B = bregler_factorization(Wc, k)
    return R, C, B, t, info


def _dai_rotations(tracks, k: int, *, seed: int, n_starts: int, completion_steps: int = 100,
                   completion=None, start=None):
    """``dai``'s first stage at K: the centred tracks (2F, P), translations (F, 2), the record and the
    rotations (F, 3, 3) of the corrective triple, before their per-frame signs are resolved
    (:func:`orient_frames` needs the shapes). ``completion_steps``: the cap on the completion's steps
    (fewer than its default 100 only for an estimate, :meth:`lipgen.nrsfm.kscan.DaiScan.estimate`);
    ``completion``, ``start``: as :func:`_centred`."""
    Wc, t, info = _centred(tracks, k, completion_steps, completion, start)
    M, _, _ = factor(Wc, min(3 * k, info["rank"]))
    g, cost = corrective_triple(M, n_starts=n_starts, seed=seed)
    R, _ = rotations_from_triple(M, g)
    info["rotation_cost"] = cost
    return Wc, t, info, R


def _dai_parts(tracks, k: int, method: str, *, seed: int, n_starts: int, shape_starts: int,
               rotations=None):
    """``dai``'s answer ``(R, C, B, t)``, the K-shape fit ``(R, C, B, t)`` that starts ``dai-ba``
    (``dai``'s answer when no fit is made), and the record; ``rotations``: the first stage's output
    (:func:`_dai_rotations`) when it was already run."""
    if rotations is None:
        rotations = _dai_rotations(tracks, k, seed=seed, n_starts=n_starts)
    Wc, t, info, R = rotations
    info = dict(info)
    rank = info["rank"]
    mask = None if tracks.complete else tracks.mask
    shapes = min_trace_norm_shapes(Wc, R, mask)
    R, shapes, _ = orient_frames(R, shapes)
    info.update(trace_norm_shapes=shape_figures(R, shapes))
    # with R fixed, exactly K basis shapes fitted to the tracks from the trace-norm cut: the
    # answer when it explains the tracks exactly (noise-free K shapes), else only dai-ba's start.
    # Complete tracks of numerical rank > 3K cannot be explained exactly: no fit for dai then.
    C, B = rank_k_shapes(shapes, k)
    fit = {"shape_exact": False}
    fitted = (R, C, B, t)
    # with points missing, an exact K-shape fit needs the rank-3K completion to fit the observed
    # points (nearly) exactly; else (real tracks) the fit could only be discarded: skipped
    if method == "dai-ba" or rank <= 3 * k or (not tracks.complete and info["completion_misfit"]
                                               <= _EXACT_COMPLETION):
        C, B, shift, fit = fit_rank_k(Wc, R, B, mask, exact_model=rank <= 3 * k, n_starts=shape_starts,
                                      seed=seed)
        info.update(fit)
        fitted = (R, C, B, t + shift)
    fitted = _tidy(*fitted)
    info["rank_k_reprojection_rms"] = _reprojection_rms(tracks, *fitted)
    if fit["shape_exact"]:
        info["shapes"] = "rank-K fit"
        return fitted, fitted, info
    # Dai's trace-norm shapes (the block matrix method as published): on held-out bodies the
    # rank-K fit inflated depth (e3D up to 19 where these gave 0.16; see lipgen.nrsfm.plausibility)
    info["shapes"] = "trace norm"
    C, B = _as_basis(shapes)
    return _tidy(R, C, B, t), fitted, info


def _refine(tracks, answer, fitted, info, *, refine_iter: int):
    """``dai-ba``: bundle adjustment from the K-shape fit, kept by :func:`lipgen.nrsfm.keep.keep_refinement`
    (lower reprojection error than its start, depth ratio and depth roughness within 1.5 times those of
    ``dai``'s answer, plausible against Dai's trace-norm shapes), else ``dai``'s answer as it is."""
    mask = None if tracks.complete else tracks.mask
    Rb, Cb, Bb, tb, history = bundle_adjust(tracks.W, *fitted, mask, max_iter=refine_iter)
    refined = shape_figures(Rb, np.einsum("fk,kip->fip", Cb, Bb))
    start = shape_figures(answer[0], np.einsum("fk,kip->fip", answer[1], answer[2]))
    keep = keep_refinement(history, refined, start, info["trace_norm_shapes"])
    info.update(ba_cost=[history[0], history[-1]], ba_steps=len(history) - 1, ba_shapes=refined,
                ba_start_shapes=start, ba_kept=keep)
    if keep:
        return Rb, Cb, Bb, tb
    log.info("bundle adjustment rejected (cost %.3g -> %.3g; depth ratio %.3g against dai's %.3g, depth "
             "roughness %.3g against dai's %.3g): returning dai's answer", history[0], history[-1],
             refined["depth_ratio"], start["depth_ratio"], refined["depth_roughness"],
             start["depth_roughness"])
    return answer


def _reconstruct(W, k, method: str, visible, *, seed: int, n_starts: int, shape_starts: int,
                 refine_iter: int, em_iter: int, tracks=None, rotations=None) -> Reconstruction:
    if tracks is None:
        tracks = check_tracks(W, visible)
    F, P = tracks.mask.shape
    k = check_method_k(k, method, F, P, tracks.n_observed)
    if method == "em-pnd":  # started from dai at K + 1 basis shapes (lipgen.nrsfm.empnd)
        start = _reconstruct(W, k + 1, "dai", visible, seed=seed, n_starts=n_starts,
                             shape_starts=shape_starts, refine_iter=refine_iter, em_iter=em_iter)
        R, C, B, t, info = pnd_reconstruction(tracks, k, start, max_iter=em_iter)
        return Reconstruction(rotations=R, weights=C, basis=B, translation=t, method=method, k=k,
                              reprojection_rms=_reprojection_rms(tracks, R, C, B, t), info=info)
    if method == "em-ppca":
        R, C, B, t, info = em_ppca(tracks, k, max_iter=em_iter, n_starts=n_starts, seed=seed)
        return Reconstruction(rotations=R, weights=C, basis=B, translation=t, method=method, k=k,
                              reprojection_rms=_reprojection_rms(tracks, R, C, B, t), info=info)
    if method == "bregler":
        R, C, B, t, info = _bregler(tracks, k)
    else:
        (R, C, B, t), fitted, info = _dai_parts(tracks, k, method, seed=seed, n_starts=n_starts,
                                                shape_starts=shape_starts, rotations=rotations)
        if method == "dai-ba":
            R, C, B, t = _refine(tracks, (R, C, B, t), fitted, info, refine_iter=refine_iter)
    rms = _reprojection_rms(tracks, R, C, B, t)
    return Reconstruction(rotations=R, weights=C, basis=B, translation=t, method=method, k=k,
                          reprojection_rms=rms, info=info)
