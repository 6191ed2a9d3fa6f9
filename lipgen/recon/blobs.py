"""Dots the top-hat cannot resolve: blob peaks of the Laplacian of Gaussian.

On the ``hard`` preset the mirror view is out of focus, and a dot next to a darker structure (the
lip border, the mouth line, a shadow) spreads into it: the top-hat response
(:func:`lipgen.recon.dots.darkness`) then rises through the dot to the structure with no peak of
its own. The dot is still a bump in curvature, which the scale-normalised Laplacian of Gaussian
sees as a local maximum. On the development set ``hard`` 53 (main's tracks, truth for diagnosis),
162 mirror sightings visible but lost: 105 have no top-hat peak within 1.5 px of the truth even
with no floor at all, though 99 of them are seen in the direct view; the Laplacian at ``sigma``
has a peak within 1.5 px for 90 of the 105 (and for 421 of the 428 accepted ones). It also has
about five times the top-hat's peaks away from any marker (skin, teeth, shading), so these peaks
are offered only where the tracker already knows where to look: along the other view's epipolar
line (:func:`lipgen.recon.epipolar.recover_along_epipolar`) and, with
``TrackerSettings.blobs``, near the prediction of a marker that has no round dot there
(:func:`blob_candidates`, :class:`lipgen.recon.track.MarkerTracker`).

A dot seen obliquely is the other kind the tracker needs help with: an elongated top-hat peak that the
roundness test rejects (:func:`foreshortened_dots`).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from lipgen.recon.dots import (
    DotSettings,
    _dedupe,
    dot_response,
    local_maxima,
    peak_roundness,
    refine_centroids,
    refine_peaks,
)

__all__ = ["blob_peaks", "blob_candidates", "blob_allowed", "foreshortened_dots", "near_centres"]


def near_centres(points: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """(m,) bool: which ``points`` (m, 2) lie within ``radii`` (n,) of any of ``centres`` (n, 2)."""
    if len(points) == 0 or len(centres) == 0:
        return np.zeros(len(points), dtype=bool)
    return (np.linalg.norm(points[:, None] - centres[None], axis=2) <= radii[None]).any(1)


def blob_peaks(gray: np.ndarray, settings: DotSettings, exclude: np.ndarray | None = None,
               response: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Round dark blobs by the Laplacian of Gaussian at ``settings.sigma``, strongest first.

    Parameters
    ----------
    gray : (h, w) float
    settings : DotSettings
        ``sigma``, ``noise_k`` (the robust noise floor of the Laplacian, as :func:`dot_peaks`
        uses it for the top-hat), ``min_roundness``, ``separation``.
    exclude : (m, 2) float, optional
        Peaks already found (column, row): blobs within ``separation`` of one are left out.
    response : (h, w) float, optional
        The detector's response of ``gray`` (:func:`lipgen.recon.dots.dot_response`) if the
        caller has it (the tracker does): not computed again.

    Returns
    -------
    uv : (k, 2) float
        Whole-pixel peaks (column, row).
    strength : (k,) float
        The smoothed top-hat darkness there (the scale of :func:`dot_peaks`' strength), not the
        Laplacian: the tracker compares it with the marker's own dot.
    """
    if settings.blob_response == "hessian":
        rows, cols = _pit_peaks(gray, settings)
    else:
        s = settings.sigma
        # A dark blob is a minimum of the image: its Laplacian is positive; s^2 normalises the scale.
        lap = s * s * ndimage.gaussian_laplace(gray, s, mode="nearest")
        rows, cols = np.nonzero(local_maxima(lap, settings, -np.inf))    # the noise floor only
        keep = peak_roundness(lap, rows, cols)[0] >= settings.min_roundness
        rows, cols = rows[keep], cols[keep]
    uv = np.column_stack([cols, rows]).astype(np.float64)
    if exclude is not None and len(exclude) and len(uv):
        far = np.linalg.norm(uv[:, None] - np.asarray(exclude)[None], axis=2).min(1) >= settings.separation
        uv, rows, cols = uv[far], rows[far], cols[far]
    if response is None:
        response = dot_response(gray, settings)
    strength = response[rows, cols]
    order = np.argsort(-strength, kind="stable")
    return uv[order], strength[order]


def pit_response(gray: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """The principal curvatures of ``gray`` (h, w) smoothed at ``scale`` pixels, scale-normalised
    (times ``scale**2``): (smaller, larger), each (h, w). A dark dot is a pit, both positive; a
    slope, or a slit like the mouth opening, has the smaller near 0 or negative."""
    hxx = ndimage.gaussian_filter(gray, scale, order=(0, 2), mode="nearest")
    hyy = ndimage.gaussian_filter(gray, scale, order=(2, 0), mode="nearest")
    hxy = ndimage.gaussian_filter(gray, scale, order=(1, 1), mode="nearest")
    half_trace, root = 0.5 * (hxx + hyy), np.sqrt(0.25 * (hxx - hyy) ** 2 + hxy ** 2)
    return scale * scale * (half_trace - root), scale * scale * (half_trace + root)


def _pit_peaks(gray: np.ndarray, settings: DotSettings) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) of the maxima of the smaller curvature (:func:`pit_response` at 0.7 sigma,
    which resolves a dot beside a dark slit better than sigma: measured on ``default`` development
    sets, 563 against 444 of 627 shoulder dots), over the noise floor, at least
    ``min_foreshortened_roundness`` round."""
    small, large = pit_response(gray, 0.7 * settings.sigma)
    pit = np.maximum(small, 0.0)
    rows, cols = np.nonzero(local_maxima(pit, settings, 0.0))
    keep = small[rows, cols] >= settings.min_foreshortened_roundness * large[rows, cols]
    return rows[keep], cols[keep]


def blob_candidates(gray: np.ndarray, response: np.ndarray, lo: np.ndarray, settings: DotSettings,
                    centres: np.ndarray, radii: np.ndarray, exclude: np.ndarray, full: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Unresolved dots near ``centres``: blob peaks of the search region, sub-pixel.

    Parameters
    ----------
    gray, response : (h, w) float
        The tracker's search region (ink grey) and its detector response.
    lo : (2,) int
        The region's top-left pixel in the image (column, row).
    settings : DotSettings
    centres : (n, 2) float, radii : (n,) float
        Only blobs within ``radii`` of a centre (image pixels) are kept.
    exclude : (m, 2) float
        What the top-hat found (image pixels): blobs within ``separation`` are left out.
    full : (H, W) float
        The whole ink image, for the sub-pixel fit.

    Returns
    -------
    uv : (k, 2) float
        Image pixels; a fit that moves more than half a separation from its peak (pulled onto
        the darker structure beside it) keeps the peak.
    strength : (k,) float
        Top-hat darkness at the peak.
    """
    if len(centres) == 0:
        return np.zeros((0, 2)), np.zeros(0)
    uv, strength = blob_peaks(gray, settings, np.asarray(exclude) - lo, response)
    uv = uv + lo
    near = near_centres(uv, centres, radii)
    uv, strength = uv[near], strength[near]
    if len(uv) == 0:
        return uv, strength
    fit, kept = refine_peaks(full, uv, settings)   # two peaks that converge to one dot: one candidate
    uv, strength = uv[kept], strength[kept]
    moved = np.linalg.norm(fit - uv, axis=1) > settings.separation / 2
    return np.where(moved[:, None], uv, fit), strength


def blob_allowed(blobs: np.ndarray, strength: np.ndarray, guess: np.ndarray, cand: np.ndarray,
                 reach: np.ndarray, gates: np.ndarray, need: np.ndarray, own: np.ndarray,
                 ratios: tuple[float, float]) -> np.ndarray:
    """(P, k) bool: which marker may take which blob.

    Marker i may take blob j when it ``need`` s one (no round dot at its prediction), its own
    dot's darkness ``own[i]`` is known and ``strength[j]`` is within ``ratios`` (least, most)
    of it, blob j is within ``reach[i]`` of its ``guess[i]`` or ``gates[i]`` of its ``cand[i]``
    (all (P, 2) / (P,)), and no other placed marker's guess is nearer to the blob (it is not a
    neighbour's unresolved dot).
    """
    P, k = len(guess), len(blobs)
    if k == 0:
        return np.zeros((P, 0), dtype=bool)
    placed = np.all(np.isfinite(guess), axis=1)
    d_guess = np.where(placed[:, None], np.linalg.norm(guess[:, None] - blobs[None], axis=2), np.inf)
    d_cand = np.where(placed[:, None], np.linalg.norm(cand[:, None] - blobs[None], axis=2), np.inf)
    ok = (d_guess <= reach[:, None]) | (d_cand <= gates[:, None])
    ok &= d_guess == d_guess.min(0, keepdims=True)
    ok &= (need & np.isfinite(own))[:, None]
    with np.errstate(invalid="ignore"):
        ok &= (strength[None] >= ratios[0] * own[:, None]) & (strength[None] <= ratios[1] * own[:, None])
    return ok


def foreshortened_dots(gray: np.ndarray, dots: np.ndarray, peaks: np.ndarray, centres: np.ndarray,
                       radii: np.ndarray, settings: DotSettings) -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel centres of the elongated ``peaks`` (m, 2) within ``radii`` (n,) + 1 px of
    ``centres`` (n, 2): dots seen obliquely, which the roundness test rejects.

    Refined together with the round ``dots`` (k, 2) near them (deblending), and dropped where
    they end on a round dot. Only markers whose own dot was not found need them, so this is
    usually empty and costs nothing. Returns (uv (j, 2), index (j,) into ``peaks``).
    """
    idx = np.flatnonzero(near_centres(peaks, centres, radii + 1.0))
    if len(idx) == 0:
        return np.zeros((0, 2)), idx
    reach = 2 * (np.ceil(3.0 * settings.sigma) + 1)
    nb = (np.linalg.norm(dots[:, None] - peaks[idx][None], axis=2) < reach).any(1)
    uv = refine_centroids(gray, np.vstack([peaks[idx], dots[nb]]), settings.sigma,
                          window=None)[:len(idx)]   # elongated blobs: the whole patch
    sep = settings.separation / 2
    ok = _dedupe(uv, sep)
    if len(dots):
        ok &= np.linalg.norm(uv[:, None] - dots[None], axis=2).min(1) >= sep
    return uv[ok], idx[ok]
