"""The time prior of hidden track entries, and their fill from a low-rank model and that prior.

A hidden entry's prior is its own point's track interpolated linearly in time between the frames that
see it (:func:`interpolate_in_time`); its expected squared error is measured on the observed entries
themselves (:func:`prior_variance`). :func:`fill_hidden` combines the prior with the model of
:mod:`lipgen.nrsfm.completion` by least squares, each weighted by its variance.
"""

from __future__ import annotations

import numpy as np

__all__ = ["interpolate_in_time", "prior_variance", "fill_hidden"]


def interpolate_in_time(W: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Each point's hidden coordinates interpolated linearly in time from the frames that see it.

    Parameters
    ----------
    W : (2F, P) float
        Tracks; entries at hidden points are ignored.
    mask : (F, P) bool
        Observed points (every point seen at least once).

    Returns
    -------
    (2F, P) float
        W with the hidden entries filled (held constant before the first and after the last sighting).
    """
    F, P = mask.shape
    out = W.copy()
    frames = np.arange(F)
    for p in range(P):
        seen = mask[:, p]
        if seen.all():
            continue
        for axis in (0, 1):
            track = W[axis::2, p]
            out[axis::2, p] = np.where(seen, track, np.interp(frames, frames[seen], track[seen]))
    return out


def prior_variance(W: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Expected squared error of :func:`interpolate_in_time` at each hidden entry, measured on the
    observed entries themselves (no truth): at m frames from the nearest sighting, the mean square of
    ``w_f - (w_{f-m} + w_{f+m}) / 2`` over the points seen at f - m, f and f + m (the middle of a gap
    of 2m - 1 frames). A distance never measured takes the largest measured one's value times
    (m / m')^2; 0 at observed entries.

    Parameters
    ----------
    W : (2F, P) float
    mask : (F, P) bool

    Returns
    -------
    (2F, P) float
    """
    F, P = mask.shape
    dist = _frames_to_sighting(mask)
    Wf = W.reshape(F, 2, P)
    var = np.zeros((F, P))
    known: dict[int, float] = {}
    for m in np.unique(dist[dist > 0]):
        m = int(m)
        if 2 * m < F:
            ok = mask[m:F - m] & mask[: F - 2 * m] & mask[2 * m:]
            if ok.sum() >= 10:
                err = Wf[m:F - m] - 0.5 * (Wf[: F - 2 * m] + Wf[2 * m:])
                known[m] = float(((err**2).sum(1))[ok].mean()) / 2
        if m not in known:
            last = max(known) if known else None
            known[m] = np.inf if last is None else known[last] * (m / last) ** 2
        var[dist == m] = known[m]
    return np.repeat(var, 2, axis=0)


def _frames_to_sighting(mask: np.ndarray) -> np.ndarray:
    """(F, P) int: frames from each entry to the nearest frame where its point is seen (0 where seen),
    by a forward and a backward running extreme of the sighting frames (O(F P), not O(F^2 P))."""
    F = mask.shape[0]
    frames = np.arange(F)[:, None]
    far = 2 * F                                                   # beyond any real distance
    last = np.maximum.accumulate(np.where(mask, frames, -far), axis=0)
    nxt = np.minimum.accumulate(np.where(mask, frames, 3 * F)[::-1], axis=0)[::-1]
    return np.minimum(frames - last, nxt - frames)


def fill_hidden(W0: np.ndarray, prior: np.ndarray, mask: np.ndarray, N: np.ndarray, noise: float
                ) -> np.ndarray:
    """Hidden entries x of each row: the model (``N_H^T x = -N^T w~``, residual variance ``noise``)
    and the prior (variance :func:`prior_variance` per entry) combined by least squares.

    Parameters
    ----------
    W0 : (2F, P) float
        Tracks with zeros at the hidden entries.
    prior : (2F, P) float
        :func:`interpolate_in_time` of the tracks.
    mask : (F, P) bool
        Observed points.
    N : (P, d) float
        Orthonormal basis of the complement of the model's row space.
    noise : float
        The model's residual variance per entry.

    Returns
    -------
    (2F, P) float
        W0 with its hidden entries filled.
    """
    F, P = mask.shape
    full = W0.reshape(F, 2, P).copy()
    x0 = prior.reshape(F, 2, P)
    floor = 1e-24 * max(float(np.mean(W0**2)), 1e-300)              # exact priors, without overflow
    weight = 1.0 / np.maximum(prior_variance(W0, mask)[::2], floor)      # (F, P)
    hidden = (~mask).sum(1)
    for h in np.unique(hidden[hidden > 0]):
        frames = np.flatnonzero(hidden == h)
        idx = np.nonzero(~mask[frames])[1].reshape(frames.size, h)
        NH = N[idx]                                               # (n, h, d)
        start = np.take_along_axis(x0[frames], idx[:, None, :], axis=2)   # (n, 2, h)
        D = np.take_along_axis(weight[frames], idx, axis=1)      # (n, h)
        # min |(k + x NH)| / sqrt(noise) + sum D (x - start)^2 as one stacked least-squares problem,
        # the model's rows first (Householder QR with the heavy rows on top stays accurate where the
        # normal equations would lose D under NH NH^T / noise: noise at its floor made them singular)
        root = np.sqrt(D)
        M = np.concatenate([NH.transpose(0, 2, 1) / np.sqrt(noise), root[:, :, None] * np.eye(h)], axis=1)
        b = np.concatenate([-(full[frames] @ N).transpose(0, 2, 1) / np.sqrt(noise),
                            (start * root[:, None, :]).transpose(0, 2, 1)], axis=1)   # (n, d + h, 2)
        Q, R = np.linalg.qr(M)
        x = np.linalg.solve(R, Q.transpose(0, 2, 1) @ b).transpose(0, 2, 1)
        rows = full[frames]
        np.put_along_axis(rows, idx[:, None, :].repeat(2, axis=1), x, axis=2)
        full[frames] = rows
    return full.reshape(2 * F, P)
