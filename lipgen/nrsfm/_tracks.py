"""Tracking matrices: checks, centring, low-rank completion of unobserved entries, factorisation.

A tracking matrix ``W`` is ``(2F, P)`` with rows ``u1, v1, u2, v2, ...`` (Bregler's layout).
An optional visibility mask ``(F, P)`` marks the observed points; unobserved entries may hold
anything (NaN included) and are never read.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from lipgen._validate import as_float_array

__all__ = ["Tracks", "check_tracks", "check_k", "complete_tracks", "factor", "numerical_rank"]

log = logging.getLogger(__name__)

RANK_RTOL = 1e-9
"""Singular values below this fraction of the largest count as zero (rank decisions)."""


@dataclass(frozen=True)
class Tracks:
    """Checked tracks.

    Attributes
    ----------
    W : (2F, P) float
        The tracks, unobserved entries set to 0.
    mask : (F, P) bool
        True where a point is observed.
    """

    W: np.ndarray
    mask: np.ndarray

    @property
    def n_frames(self) -> int:
        return self.mask.shape[0]

    @property
    def n_points(self) -> int:
        return self.mask.shape[1]

    @property
    def complete(self) -> bool:
        return bool(self.mask.all())

    @property
    def n_observed(self) -> int:
        return int(self.mask.sum())


def check_tracks(W, visible=None) -> Tracks:
    """Check a tracking matrix and its optional visibility mask.

    Parameters
    ----------
    W : (2F, P) array_like
        Rows u1, v1, u2, v2, ... Unobserved entries (``visible`` False) may be NaN.
    visible : (F, P) array_like of bool, optional
        Observed points. Without it every entry must be finite.

    Raises
    ------
    ValueError
        For an odd number of rows, NaNs without a mask, a mask of the wrong shape, NaNs at
        observed entries, frames or points observed too rarely, constant tracks, or tracks of
        numerical rank below 3 (not even a rigid motion).
    """
    W = as_float_array(W, "W", (None, None), finite=False)
    n_rows, n_points = W.shape
    if n_rows % 2:
        raise ValueError(
            f"W must have 2F rows (u1, v1, u2, v2, ... one pair per frame), but its shape {W.shape} "
            f"has an odd number of rows ({n_rows}); drop the unpaired row or add the missing one"
        )
    n_frames = n_rows // 2
    if n_frames < 2 or n_points < 4:
        raise ValueError(
            f"W of shape {W.shape} holds {n_frames} frame(s) of {n_points} point(s); structure from "
            "motion needs at least 2 frames and 4 points"
        )
    if visible is None:
        bad = ~np.isfinite(W)
        if bad.any():
            r, c = (int(i) for i in np.argwhere(bad)[0])
            raise ValueError(
                f"W of shape {W.shape} has {int(bad.sum())} NaN/inf entries (the first at row {r}, "
                f"column {c}) and no visibility mask; pass visible=(F, P) bool marking the observed "
                "points (False where a track is missing)"
            )
        mask = np.ones((n_frames, n_points), dtype=bool)
    else:
        mask = np.asarray(visible)
        if mask.shape != (n_frames, n_points):
            raise ValueError(
                f"visible must have shape (F, P) = ({n_frames}, {n_points}) for W of shape {W.shape}, "
                f"got {mask.shape}"
            )
        if mask.dtype != bool:
            if not np.isin(mask, (0, 1)).all():
                raise ValueError(f"visible must be boolean (or 0/1), got dtype {mask.dtype}")
            mask = mask.astype(bool)
        seen = np.repeat(mask, 2, axis=0)
        bad = seen & ~np.isfinite(W)
        if bad.any():
            r, c = (int(i) for i in np.argwhere(bad)[0])
            raise ValueError(
                f"W has {int(bad.sum())} NaN/inf entries marked visible (the first at row {r}, column "
                f"{c}); set visible[{r // 2}, {c}] = False or fix the track"
            )
        _check_coverage(mask)
    W = np.where(np.repeat(mask, 2, axis=0), W, 0.0)
    tracks = Tracks(W=W, mask=mask)
    _check_content(tracks)
    return tracks


def _check_coverage(mask: np.ndarray) -> None:
    per_frame = mask.sum(1)
    per_point = mask.sum(0)
    if (per_frame < 3).any():
        f = int(np.flatnonzero(per_frame < 3)[0])
        raise ValueError(
            f"frame {f} observes only {int(per_frame[f])} point(s) (visible of shape {mask.shape}); "
            "every frame needs at least 3 observed points: drop such frames"
        )
    if (per_point < 2).any():
        p = int(np.flatnonzero(per_point < 2)[0])
        raise ValueError(
            f"point {p} is observed in only {int(per_point[p])} frame(s) (visible of shape {mask.shape}); "
            "every point needs at least 2 observations: drop such points"
        )


def _check_content(tracks: Tracks) -> None:
    W, mask = tracks.W, tracks.mask
    seen = np.repeat(mask, 2, axis=0)
    means = (W * seen).sum(1) / seen.sum(1)
    Wc = np.where(seen, W - means[:, None], 0.0)
    scale = max(float(np.abs(W).max()), 1.0)
    if float(np.abs(Wc).max()) <= 1e-12 * scale:
        raise ValueError(
            f"W of shape {W.shape} is constant within every frame (all points project to one place, "
            "or W is all zero): there is no shape to reconstruct"
        )
    if tracks.complete:
        rank, s = numerical_rank(Wc)
        if rank < 3:
            raise ValueError(
                f"the centred tracks W of shape {W.shape} have numerical rank {rank} < 3 (singular "
                f"values {np.array2string(s[:4], precision=3)}): the points are collinear in every image "
                "or move in a plane, so not even a rigid 3D structure is defined; check the tracks"
            )


def numerical_rank(Wc: np.ndarray, rtol: float = RANK_RTOL) -> tuple[int, np.ndarray]:
    """Numerical rank of a centred matrix and its singular values."""
    s = np.linalg.svd(Wc, compute_uv=False)
    if s[0] == 0:
        return 0, s
    return int((s > rtol * s[0]).sum()), s


def check_k(k, n_frames: int, n_points: int, n_observed: int | None = None,
            unknowns_per_frame: int = 0) -> int:
    """Check the number of basis shapes K against the size of the data.

    The rank-3K factorisation needs ``3K <= min(2F, P - 1)`` (centred tracks have rank at most
    ``P - 1``). The shape model has ``K (F + 3P)`` unknowns plus ``unknowns_per_frame`` per frame
    (rotation, translation); they must be fewer than the ``2 * n_observed`` measured coordinates.
    """
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)):
        raise TypeError(f"k (number of basis shapes) must be an integer, got {k!r}")
    k = int(k)
    limit = min(2 * n_frames, n_points - 1) // 3
    if k < 1:
        raise ValueError(f"k (number of basis shapes) must be at least 1, got {k}")
    if k > limit:
        raise ValueError(
            f"k={k} is too large for tracks of {n_frames} frames and {n_points} points: the rank-3K "
            f"factorisation needs 3K <= min(2F, P - 1) = {min(2 * n_frames, n_points - 1)}, so k <= {limit}"
        )
    n_obs = n_frames * n_points if n_observed is None else n_observed
    unknowns = k * (n_frames + 3 * n_points) + unknowns_per_frame * n_frames
    if unknowns >= 2 * n_obs:
        raise ValueError(
            f"k={k} gives {unknowns} unknowns (K(F + 3P) + {unknowns_per_frame}F) but the tracks hold only "
            f"{2 * n_obs} observed coordinates; use a smaller k"
        )
    return k


def complete_tracks(tracks: Tracks, rank: int, max_iter: int = 100, tol: float = 1e-9,
                    return_residual: bool = False, resume=None, start=None):
    """Tracks with unobserved entries filled from the best rank-``rank`` model plus translation.

    Fits ``W ~ M B + t 1^T`` (M: 2F x rank, B: rank x P, t: per-row translation) to the observed
    entries by Gauss-Newton on the model's row space (:func:`lipgen.nrsfm.completion.complete_subspace`);
    each hidden entry is then the least-squares combination of what the model says and of the
    point's track interpolated in time (weighted by their measured errors). Complete tracks are
    returned unchanged. ``resume``: a stopped completion of these tracks at this rank to go on with
    (:class:`lipgen.nrsfm.completion.SubspaceCompletion`); ``start``: complete rows over the same points
    to start the fit from (:func:`lipgen.nrsfm.completion.complete_subspace`).

    Returns
    -------
    (2F, P) float
        The completed tracks.
    residual : float
        Only with ``return_residual``: RMS misfit of the model on the observed entries over their
        RMS about each row's mean (0 for complete tracks, ~1e-15 for exact low-rank ones).
    """
    from lipgen.nrsfm.completion import complete_subspace

    W = tracks.W
    if tracks.complete:
        return (W.copy(), 0.0) if return_residual else W.copy()
    full, misfit, _ = complete_subspace(W, tracks.mask, rank, max_iter=max_iter, tol=tol, resume=resume,
                                        start=start)
    return (full, misfit) if return_residual else full


def factor(Wc: np.ndarray, r: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rank-``r`` factorisation ``Wc ~ M B`` by SVD, the singular values split evenly (eq 6).

    Returns
    -------
    M : (2F, r) float
    B : (r, P) float
    s : (min(2F, P),) float
        All singular values of ``Wc``.
    """
    U, s, Vt = np.linalg.svd(Wc, full_matrices=False)
    root = np.sqrt(s[:r])
    # A deterministic sign per singular pair, so results do not depend on the LAPACK build.
    flip = np.sign(U[np.argmax(np.abs(U[:, :r]), axis=0), np.arange(r)])
    flip[flip == 0] = 1.0
    return U[:, :r] * (root * flip), (root * flip)[:, None] * Vt[:r], s
