"""``reconstruct``: one entry point for every method, and the result record."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from lipgen._threads import single_threaded
from lipgen.nrsfm._rotation import corrective_triple, orient_frames, rotations_from_triple
from lipgen.nrsfm._tracks import check_k, check_tracks, complete_tracks, factor, numerical_rank
from lipgen.nrsfm.bmm import min_trace_norm_shapes, rank_k_shapes
from lipgen.nrsfm.bregler import bregler_factorization
from lipgen.nrsfm.emppca import em_ppca
from lipgen.nrsfm.lowrank import fit_rank_k
from lipgen.nrsfm.plausibility import plausible, shape_figures
from lipgen.nrsfm.refine import bundle_adjust

__all__ = ["Reconstruction", "reconstruct", "curve_values", "choose_k",
           "METHODS", "DEFAULT_METHOD", "MEAN_PLUS_MODES", "n_basis_shapes",
           "check_method_k"]

log = logging.getLogger(__name__)

METHODS: dict[str, str] = {
    "bregler": "Bregler, Hertzmann & Biermann 1999 as written: rank-3K SVD, per-frame rank-1 "
               "pose/weights, one 3x3 metric upgrade",
    "dai": "Dai, Li & He 2012 (prior-free): rotations from the orthonormality of one corrective "
           "triple (deterministic Levenberg-Marquardt), then the shapes of least trace norm that "
           "reproject exactly (block matrix method, as published); when the tracks are exactly of rank "
           "<= 3K (noise-free K shapes) exactly K basis shapes fitted with the rotations fixed instead",
    "dai-ba": "'dai', then K basis shapes fitted with the rotations fixed and low-rank bundle adjustment "
              "(Levenberg-Marquardt on the reprojection error), kept only if its depth neither inflates "
              "nor roughens against the trace-norm shapes (lipgen.nrsfm.plausibility); else 'dai'",
    "em-ppca": "Torresani, Hertzmann & Bregler 2008 (EM-Gaussian): mean shape plus K Gaussian "
               "deformation modes, fitted by EM from a rigid start; here K counts the modes, so the "
               "model has K + 1 basis shapes (rank 3(K + 1))",
}
"""Method names accepted by :func:`reconstruct`, with what each does."""

DEFAULT_METHOD = "dai"
"""The method :func:`reconstruct` uses unless told."""

MEAN_PLUS_MODES = frozenset({"em-ppca"})
"""Methods whose ``k`` counts deformation modes beyond a mean shape (``k + 1`` basis shapes)."""


def n_basis_shapes(k: int, method: str) -> int:
    """Number of basis shapes of ``method`` run with ``k``: ``k + 1`` for em-ppca, else ``k``."""
    return k + 1 if method in MEAN_PLUS_MODES else k


def check_method_k(k, method: str, n_frames: int, n_points: int, n_observed: int) -> int:
    """:func:`check_k` for ``method``'s meaning of k (em-ppca: k >= 0 modes, k + 1 basis shapes)."""
    if method not in MEAN_PLUS_MODES:
        return check_k(k, n_frames, n_points, n_observed, unknowns_per_frame=5)
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)):
        raise TypeError(f"k (number of deformation modes) must be an integer, got {k!r}")
    if k < 0:
        raise ValueError(f"k (number of deformation modes of {method!r}) must be at least 0, got {k}")
    k = int(k)
    limit = min(2 * n_frames, n_points - 1) // 3 - 1
    if k > limit:
        raise ValueError(
            f"k={k} is too large for method {method!r} on tracks of {n_frames} frames and {n_points} "
            f"points: k deformation modes + the mean = {k + 1} basis shapes, whose rank-3(k + 1) model "
            f"needs 3(k + 1) <= min(2F, P - 1) = {min(2 * n_frames, n_points - 1)}, so k <= {limit}")
    try:
        check_k(k + 1, n_frames, n_points, n_observed, unknowns_per_frame=5)
    except ValueError as exc:
        raise ValueError(f"method {method!r} with k={k} deformation modes ({k + 1} basis shapes): "
                         f"{exc}") from None
    return int(k)


@dataclass(frozen=True)
class Reconstruction:
    """A non-rigid reconstruction under orthography (arrays are read-only).

    Attributes
    ----------
    rotations : (F, 3, 3) float
        Object-to-camera rotations; the third row is the cross product of the first two.
    weights : (F, N) float
        Configuration weights (they carry each frame's projection scale). N = K basis shapes,
        except for ``method="em-ppca"`` where N = K + 1 (mean shape first, then the K modes), and
        for ``"dai"`` (or a rejected ``"dai-ba"``) on tracks not exactly of rank <= 3K, where the
        trace-norm shapes are returned whole: N is their numerical rank (``info["shapes"]``).
    basis : (N, 3, P) float
        Basis shapes in the object frame.
    translation : (F, 2) float
        Image translation of each frame: ``W_f ~ (R_f S_f)[:2] + t_f``.
    method : str
    k : int
        The K passed to :func:`reconstruct` (for em-ppca the number of modes beyond the mean).
    reprojection_rms : float
        RMS over observed coordinates of the reprojection residual, in the units of W.
    info : dict
        Diagnostics of the method (costs, iteration counts).
    """

    rotations: np.ndarray
    weights: np.ndarray
    basis: np.ndarray
    translation: np.ndarray
    method: str
    k: int
    reprojection_rms: float
    info: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        for name in ("rotations", "weights", "basis", "translation"):
            arr = np.array(getattr(self, name), dtype=np.float64)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def n_frames(self) -> int:
        return self.rotations.shape[0]

    @property
    def n_points(self) -> int:
        return self.basis.shape[2]

    @property
    def object_shapes(self) -> np.ndarray:
        """(F, 3, P) shapes in the object frame, ``sum_k weights[f, k] basis[k]``."""
        return np.einsum("fk,kip->fip", self.weights, self.basis)

    @property
    def shapes(self) -> np.ndarray:
        """(F, 3, P) shapes in the camera frame (x right, y down as the tracks, z depth), centred."""
        # einsum, not BLAS: the same bytes whatever the caller's BLAS thread count
        return np.einsum("fij,fjp->fip", self.rotations, self.object_shapes)

    @property
    def S(self) -> np.ndarray:
        """(3F, P) camera-frame shapes, rows x1, y1, z1, x2, ... (the benchmark layout)."""
        return self.shapes.reshape(-1, self.n_points)

    def reproject(self) -> np.ndarray:
        """(2F, P) predicted tracks, rows u1, v1, u2, ..."""
        return (self.shapes[:, :2] + self.translation[:, :, None]).reshape(-1, self.n_points)


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


# one thread always: the result, not only the speed, depends on it (see lipgen._threads.blas_threads)
@single_threaded(always=True)
def reconstruct(W, k: int, method: str = DEFAULT_METHOD, visible=None, *, seed: int = 0,
                n_starts: int = 4, shape_starts: int = 8, refine_iter: int = 100,
                em_iter: int = 500) -> Reconstruction:
    """Non-rigid structure from motion: rotations, weights and basis shapes from 2D tracks.

    Parameters
    ----------
    W : (2F, P) array_like
        Tracks under (scaled) orthography, rows u1, v1, u2, v2, ...
    k : int or "auto"
        Number of basis shapes K, or ``"auto"``: K chosen from the reprojection curve of
        ``method`` (:func:`lipgen.nrsfm.reprojection_curve`, default thresholds; the curve is kept
        in ``info["k_curve"]``). For
        ``"em-ppca"`` the number of deformation modes beyond the mean shape (K >= 0, K + 1 basis
        shapes): em-ppca with K modes spans the same rank-3(K + 1) model as ``"dai"`` with K + 1.
    method : str
        One of :data:`METHODS`: ``"bregler"``, ``"dai"`` (default), ``"dai-ba"`` or ``"em-ppca"``.
    visible : (F, P) array_like of bool, optional
        Observed points; unobserved entries of W are ignored (NaN allowed there). Every method
        accepts it: the rank-3K factor is then taken from a low-rank completion of W, and
        ``"dai"`` / ``"dai-ba"`` fit the shapes to the observed points only.
    seed : int
        Seed of the random starts of the rotation search.
    n_starts : int
        Starting points of the rotation search (``"dai"``, ``"dai-ba"``).
    shape_starts : int
        Random restarts of the rank-K shape fit (``"dai"``, ``"dai-ba"``), tried only when the
        tracks are exactly of rank <= 3K and the fit from the trace-norm shapes is not exact.
    refine_iter : int
        Iteration cap of the bundle adjustment (``"dai-ba"``).
    em_iter : int
        Iteration cap of EM (``"em-ppca"``).

    Returns
    -------
    Reconstruction
        The tracks are first divided by the power of two nearest their largest magnitude (exact,
        so any scale from about 1e-301 to 1e300 is solved alike) and the shapes scaled back.

    Raises
    ------
    ValueError
        For malformed tracks (see :func:`lipgen.nrsfm._tracks.check_tracks`), an unknown method,
        or a K too large for the data.
    """
    if method not in METHODS:
        raise ValueError(f"unknown NRSfM method {method!r}; choose one of {sorted(METHODS)}")
    options = {"seed": seed, "n_starts": n_starts, "shape_starts": shape_starts, "refine_iter": refine_iter,
               "em_iter": em_iter}
    if isinstance(k, str):
        if k.strip().lower() != "auto":
            raise ValueError(f"k must be an integer (number of basis shapes) or 'auto', got {k!r}")
        ks, _, relative = curve_values(W, None, method, visible, **options)
        chosen, rule = choose_k(ks, relative)
        rec = reconstruct(W, chosen, method, visible, **options)
        rec.info["k_curve"] = {"ks": ks.tolist(), "relative": relative.tolist(), "chosen": chosen,
                               "rule": rule}
        return rec
    W, unit = _normalise_scale(W, visible)
    rec = _reconstruct(W, k, method, visible, **options)
    if unit == 1.0:
        return rec
    return Reconstruction(rotations=rec.rotations, weights=rec.weights, basis=rec.basis * unit,
                          translation=rec.translation * unit, method=rec.method, k=rec.k,
                          reprojection_rms=rec.reprojection_rms * unit, info=rec.info | {"scale": unit})


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


def _reconstruct(W, k, method: str, visible, *, seed: int, n_starts: int, shape_starts: int,
                 refine_iter: int, em_iter: int) -> Reconstruction:
    tracks = check_tracks(W, visible)
    F, P = tracks.mask.shape
    k = check_method_k(k, method, F, P, tracks.n_observed)
    if method == "em-ppca":
        R, C, B, t, info = em_ppca(tracks, k, max_iter=em_iter, n_starts=n_starts, seed=seed)
        return Reconstruction(rotations=R, weights=C, basis=B, translation=t, method=method, k=k,
                              reprojection_rms=_reprojection_rms(tracks, R, C, B, t), info=info)
    full = complete_tracks(tracks, 3 * k)
    t = full.mean(axis=1)
    Wc = full - t[:, None]
    rank, sv = numerical_rank(Wc)
    if rank < 3:
        raise ValueError(f"the centred (completed) tracks have numerical rank {rank} < 3 (singular values "
                         f"{np.array2string(sv[:4], precision=3)}): not even a rigid structure is defined")
    r = min(3 * k, rank)
    if r < 3 * k:
        log.info("tracks have numerical rank %d < 3K = %d (degenerate basis shapes); the factor keeps "
                 "rank %d", rank, 3 * k, r)
    t = t.reshape(F, 2)
    info: dict = {"rank": rank, "singular_values": sv[: 3 * k + 1].tolist()}
    if method == "bregler":
        R, C, B = bregler_factorization(Wc, k)
    else:
        M, _, _ = factor(Wc, r)
        g, cost = corrective_triple(M, n_starts=n_starts, seed=seed)
        R, _ = rotations_from_triple(M, g)
        shapes = min_trace_norm_shapes(Wc, R, None if tracks.complete else tracks.mask)
        R, shapes, _ = orient_frames(R, shapes)
        mask = None if tracks.complete else tracks.mask
        ref = shape_figures(R, shapes)
        info.update(rotation_cost=cost, trace_norm_shapes=ref)
        # with R fixed, exactly K basis shapes fitted to the tracks from the trace-norm cut: the
        # answer when it explains the tracks exactly (noise-free K shapes), else only dai-ba's start.
        # Complete tracks of numerical rank > 3K cannot be explained exactly: no fit for dai then.
        C, B = rank_k_shapes(shapes, k)
        fit = {"shape_exact": False}
        fitted = (R, C, B, t)
        if method == "dai-ba" or rank <= 3 * k or not tracks.complete:
            C, B, shift, fit = fit_rank_k(Wc, R, B, mask, exact_model=rank <= 3 * k, n_starts=shape_starts,
                                          seed=seed)
            info.update(fit)
            fitted = (R, C, B, t + shift)
        info["rank_k_reprojection_rms"] = _reprojection_rms(tracks, *_tidy(*fitted))
        if fit["shape_exact"]:
            info["shapes"] = "rank-K fit"
            R, C, B, t = _tidy(*fitted)
        else:  # Dai's trace-norm shapes (the block matrix method as published): on held-out bodies the
            # rank-K fit inflated depth (e3D up to 19 where these gave 0.16; see lipgen.nrsfm.plausibility)
            info["shapes"] = "trace norm"
            C, B = _as_basis(shapes)
            R, C, B, t = _tidy(R, C, B, t)
        if method == "dai-ba":
            Rb, Cb, Bb, tb, history = bundle_adjust(tracks.W, *_tidy(*fitted), mask, max_iter=refine_iter)
            ba = shape_figures(Rb, np.einsum("fk,kip->fip", Cb, Bb))
            keep = plausible(ba, ref)
            info.update(ba_cost=[history[0], history[-1]], ba_steps=len(history) - 1, ba_shapes=ba,
                        ba_kept=bool(keep))
            if keep:
                R, C, B, t = Rb, Cb, Bb, tb
            else:
                log.info("bundle adjustment rejected (depth ratio %.3g, depth roughness %.3g against the "
                         "trace-norm shapes' %.3g, %.3g): returning its start", ba["depth_ratio"],
                         ba["depth_roughness"], ref["depth_ratio"], ref["depth_roughness"])
    rms = _reprojection_rms(tracks, R, C, B, t)
    return Reconstruction(rotations=R, weights=C, basis=B, translation=t, method=method, k=k,
                          reprojection_rms=rms, info=info)


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
        rec = reconstruct(tracks.W, int(k), method=method,
                          visible=None if tracks.complete else tracks.mask, **options)
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
