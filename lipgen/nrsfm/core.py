"""``reconstruct``: one entry point for every method, and the result record."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from lipgen.nrsfm._rotation import corrective_triple, orient_frames, rotations_from_triple
from lipgen.nrsfm._tracks import check_k, check_tracks, complete_tracks, factor, numerical_rank
from lipgen.nrsfm.bmm import min_trace_norm_shapes, rank_k_shapes
from lipgen.nrsfm.bregler import bregler_factorization
from lipgen.nrsfm.emppca import em_ppca
from lipgen.nrsfm.lowrank import fit_rank_k
from lipgen.nrsfm.refine import bundle_adjust

__all__ = ["Reconstruction", "reconstruct", "METHODS", "DEFAULT_METHOD", "MEAN_PLUS_MODES", "n_basis_shapes",
           "check_method_k"]

log = logging.getLogger(__name__)

METHODS: dict[str, str] = {
    "bregler": "Bregler, Hertzmann & Biermann 1999 as written: rank-3K SVD, per-frame rank-1 "
               "pose/weights, one 3x3 metric upgrade",
    "dai": "Dai, Li & He 2012 (prior-free): rotations from the orthonormality of one corrective "
           "triple, shapes of least trace norm reprojecting exactly (block matrix method), cut to rank K; "
           "then exactly K basis shapes fitted to the tracks with the rotations fixed (variable "
           "projection, restarted when noise-free tracks are not fitted exactly)",
    "dai-ba": "'dai' followed by low-rank bundle adjustment of rotations, weights, basis and "
              "translation (Levenberg-Marquardt on the reprojection error)",
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
        except for ``method="em-ppca"`` where N = K + 1 (mean shape first, then the K modes).
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
        return self.rotations @ self.object_shapes

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


def _tidy(R, C, B, t):
    """Orient the frames (per-frame sign, see :func:`orient_frames`) and centre the basis shapes,
    moving their mean into the image translations."""
    R, _, sign = orient_frames(R, np.einsum("fk,kip->fip", C, B))
    C = C * sign[:, None]
    centre = B.mean(axis=2)                                    # (K, 3)
    t = t + np.einsum("fia,fa->fi", R[:, :2], C @ centre)
    return R, C, B - centre[:, :, None], t


def reconstruct(W, k: int, method: str = DEFAULT_METHOD, visible=None, *, seed: int = 0,
                n_starts: int = 4, shape_starts: int = 8, refine_iter: int = 100,
                em_iter: int = 500) -> Reconstruction:
    """Non-rigid structure from motion: rotations, weights and basis shapes from 2D tracks.

    Parameters
    ----------
    W : (2F, P) array_like
        Tracks under (scaled) orthography, rows u1, v1, u2, v2, ...
    k : int
        Number of basis shapes K (see :func:`lipgen.nrsfm.reprojection_curve` to choose it). For
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

    Raises
    ------
    ValueError
        For malformed tracks (see :func:`lipgen.nrsfm._tracks.check_tracks`), an unknown method,
        or a K too large for the data.
    """
    if method not in METHODS:
        raise ValueError(f"unknown NRSfM method {method!r}; choose one of {sorted(METHODS)}")
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
        C, B = rank_k_shapes(shapes, k)
        # the trace-norm cut is only a start: with R fixed, fit exactly K basis shapes
        C, B, shift, fit = fit_rank_k(Wc, R, B, None if tracks.complete else tracks.mask,
                                      exact_model=rank <= 3 * k, n_starts=shape_starts, seed=seed)
        R, C, B, t = _tidy(R, C, B, t + shift)
        info["rotation_cost"] = cost
        info.update(fit)
        if method == "dai-ba":
            R, C, B, t, history = bundle_adjust(tracks.W, R, C, B, t, None if tracks.complete else
                                                tracks.mask, max_iter=refine_iter)
            info["ba_cost"] = [history[0], history[-1]]
            info["ba_steps"] = len(history) - 1
    rms = _reprojection_rms(tracks, R, C, B, t)
    return Reconstruction(rotations=R, weights=C, basis=B, translation=t, method=method, k=k,
                          reprojection_rms=rms, info=info)

