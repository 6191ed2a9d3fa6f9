"""Depth you cannot trust, shrunk: split-half reliability of the recovered depth, without the truth.

Under orthography the image gives x and y; only the depth is inferred, and on short or weakly
rotating sequences it can be wrong enough that the flat answer (zero depth) is closer to the
truth. Which of the two holds cannot be read from the reprojection error (Dai's shapes reproject
exactly either way), but it shows in the depth's *reproducibility*: the sequence is split into
its even and its odd frames, each half is reconstructed on its own at the same K, and the depth
of every odd frame is compared with the mean of its two even neighbours.

If each half's depth is the truth plus an independent error, the correlation ``rho`` of the two
halves' depths is ``var(truth) / (var(truth) + var(error))``, the classical reliability, and
``rho`` times the estimate is the least-squares (Wiener) shrinkage of one half's depth towards
zero. :func:`shrink_depth` scales the camera-frame depth of the whole-sequence reconstruction by
``rho``: reproducible depth (``rho`` near 1, noise-free bodies, drink, jaws) is kept; depth that
the halves do not agree on moves towards the flat answer. ``rho`` of one half is used for the
whole sequence (not the Spearman-Brown step-up ``2 rho / (1 + rho)``), which shrinks a little
more than the model asks: a deliberate margin, since the halves' errors are not independent.

The rule (even/odd halves, ``rho`` as the factor) was chosen on development bodies (seeds 300-310,
400-410 and 700-705 of :mod:`lipgen.nrsfm.validation`, 80 frames), never on drink, jaws or a
fresh seed; the figures are in ``lipgen experiment nrsfm``.
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen.nrsfm._tracks import check_tracks
from lipgen.nrsfm.engine import reconstruct_k
from lipgen.nrsfm.record import Reconstruction, check_method_k

__all__ = ["split_half_reliability", "shrink_depth", "MIN_HALF_FRAMES"]

log = logging.getLogger(__name__)

MIN_HALF_FRAMES = 4
"""Fewest frames in each half for a reliability figure (below it the depth is left as it is)."""


def _half(W, visible, start: int):
    F2, P = W.shape
    rows = np.arange(F2).reshape(-1, 2)[start::2].ravel()
    return W[rows], None if visible is None else visible[start::2]


def _depth_correlation(z_odd: np.ndarray, z_even: np.ndarray) -> float:
    """|corr| of odd frames' depth (n, P) with the mean of their even neighbours (n + 1 or more, P)."""
    n = min(len(z_odd), len(z_even) - 1)
    a = z_odd[:n]
    b = 0.5 * (z_even[:n] + z_even[1:n + 1])
    a = a - a.mean(axis=1, keepdims=True)
    b = b - b.mean(axis=1, keepdims=True)
    den = float(np.sqrt(np.sum(a * a) * np.sum(b * b)))
    if den == 0.0:
        return 0.0
    # each half's depth is defined up to one global reflection (its own corrective transform): |corr|
    return abs(float(np.sum(a * b)) / den)


def split_half_reliability(W, k: int, visible=None, method: str = "dai", **options) -> tuple[float, dict]:
    """The depth's split-half reliability ``rho`` in [0, 1] (see the module docstring).

    Parameters
    ----------
    W : (2F, P) array_like
        Tracks, rows u1, v1, u2, v2, ...
    k : int
        Basis shapes of each half's reconstruction; lowered to the largest K a half accepts.
    visible : (F, P) array_like of bool, optional
    method : str
        Method of the halves' reconstructions (``"dai"``).
    **options
        As :func:`lipgen.nrsfm.reconstruct` (seed, n_starts, ...).

    Returns
    -------
    rho : float
        |correlation| of the odd frames' depth with the mean of their even neighbours' depth, or
        1.0 (nothing shrunk) when a half has fewer than :data:`MIN_HALF_FRAMES` frames or no K.
    record : dict
        ``rho``, ``k`` (of the halves), ``reason``.
    """
    tracks = check_tracks(W, visible)
    F, P = tracks.mask.shape
    if F // 2 < MIN_HALF_FRAMES:
        return 1.0, {"rho": 1.0, "k": None, "reason": f"{F} frames: halves too short, depth kept"}
    W = tracks.W
    vis = None if tracks.complete else tracks.mask
    halves = [_half(W, vis, start) for start in (0, 1)]
    kk = int(k)
    while kk >= 1:
        try:
            for Wh, vh in halves:
                seen = int(np.sum(vh)) if vh is not None else Wh.size // 2
                check_method_k(kk, method, Wh.shape[0] // 2, P, seen)
            break
        except ValueError:
            kk -= 1
    if kk < 1:
        return 1.0, {"rho": 1.0, "k": None, "reason": "no K fits the halves: depth kept"}
    depth = []
    for Wh, vh in halves:
        try:
            depth.append(reconstruct_k(Wh, kk, method, vh, **options).shapes[:, 2])
        except ValueError as err:  # a degenerate half (e.g. rank < 3): no figure, depth kept
            return 1.0, {"rho": 1.0, "k": kk, "reason": f"a half could not be reconstructed: {err}"}
    rho = _depth_correlation(depth[1], depth[0])
    log.info("split-half depth reliability %.3f (halves at K = %d)", rho, kk)
    return rho, {"rho": rho, "k": kk, "reason": "even / odd frames"}


def shrink_depth(rec: Reconstruction, factor: float) -> Reconstruction:
    """``rec`` with its camera-frame depth multiplied by ``factor`` (x, y and the image unchanged).

    Parameters
    ----------
    rec : Reconstruction
    factor : float
        In [0, 1]; 1 returns ``rec`` itself.

    Returns
    -------
    Reconstruction
        Same rotations and translations; the shrunk object-frame shapes ``R_f^T diag(1, 1, a) S_f``
        as weights (F, r) times basis (r, 3, P), r their numerical rank (as Dai's trace-norm shapes).
    """
    factor = float(factor)
    if not 0.0 <= factor <= 1.0:
        raise ValueError(f"factor must be in [0, 1], got {factor!r}")
    if factor == 1.0:
        return rec
    cam = rec.shapes.copy()
    cam[:, 2] *= factor
    obj = np.einsum("fji,fjp->fip", rec.rotations, cam)          # R_f^T S_f
    F, _, P = obj.shape
    U, s, Vt = np.linalg.svd(obj.reshape(F, -1), full_matrices=False)
    r = max(int((s > 1e-9 * s[0]).sum()), 1) if s[0] > 0 else 1
    info = rec.info | {"depth_factor": factor}
    return Reconstruction(rotations=rec.rotations, weights=U[:, :r] * s[:r], basis=Vt[:r].reshape(r, 3, P),
                          translation=rec.translation, method=rec.method, k=rec.k,
                          reprojection_rms=rec.reprojection_rms, info=info)
