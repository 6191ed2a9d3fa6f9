"""Dark ink dots in an image: detection and sub-pixel centroids.

The thesis marked the lips with ink (§3). A dot is a small dark blob on skin or lip, so the
detector works on the *darkness* left after removing everything larger than a dot: a grey-level
closing with a disc a little wider than the dot fills the dots in and keeps the shading, and
``closing - image`` (a black top-hat) is then the dots alone on a flat, zero background. Peaks of
that response, smoothed by the dot's own Gaussian (a matched filter), are the candidates. Each
is refined to sub-pixel by fitting a Gaussian dot on a quadratic background to the image patch
around it (a plain centroid of the top-hat is pulled by shading and texture gradients: 0.3 px
on a blotchy background where the fit stays below 0.1 px).

Pixel (0, 0) is the centre of the top-left pixel and ``uv = (column, row)``, as in OpenCV.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from lipgen._threads import single_threaded
from lipgen._validate import as_float_array

__all__ = ["DotSettings", "as_gray", "ink_gray", "darkness", "dot_response", "detect_dots", "dot_peaks",
           "local_maxima", "peak_roundness", "refine_peaks", "refine_centroids"]


BLOB_RESPONSES = ("log", "hessian")


@dataclass(frozen=True)
class DotSettings:
    """How dots look in the image.

    Attributes
    ----------
    sigma : float
        Gaussian radius of a dot in pixels (a disc of radius r is close to sigma = r / 2).
    min_contrast : float
        Least darkness (fraction of full scale, 0..1) of a dot's smoothed peak in
        :func:`ink_gray`. Ink dots there reach 0.35-0.7 in our renders; skin texture and shading
        stay under 0.07.
    noise_k : float
        A peak must also exceed ``noise_k`` robust standard deviations of the response.
    min_separation : float
        Two peaks closer than this (pixels) are one dot. Defaults to ``2 * sigma``.
    smoothing : float
        The response is smoothed by ``smoothing * sigma`` before peaks are picked: 1 is the
        matched filter (best against noise), smaller keeps close pairs of dots apart (at 0.6,
        dots of sigma 1.3 px are resolved from 4 px apart, against 5 px at 1).
    min_roundness : float
        Least ratio of the weaker to the stronger principal curvature of the response at a peak:
        1 for a round dot, 0 along a line; rejects the mouth slit and creases.
    min_foreshortened_roundness : float
        Least roundness of a *candidate* peak (:func:`dot_peaks`): an ink dot on skin
        turning away from the camera (the lip corner in a side view) is an ellipse and may fall
        below ``min_roundness``; such blobs are kept as candidates that a tracker may snap to
        only where its correlation already found the marker.
    blob_response : str
        What :func:`lipgen.recon.blobs.blob_peaks` (dots the top-hat cannot resolve) looks for
        maxima of: ``"log"``, the scale-normalised Laplacian of Gaussian at ``sigma``, kept where
        round (``min_roundness``); ``"hessian"``, the smaller principal curvature of the image
        smoothed at ``0.7 * sigma`` (scale-normalised), which is positive only where the image
        curves up both ways (a pit, not a slope or a slit), so a dot on the shoulder of the dark
        mouth opening keeps a maximum of its own. Default ``"hessian"`` (xc27).
    window : float or None
        Weight window of the sub-pixel fit, in ``sigma`` (:func:`refine_centroids`); None: the
        plain fit. From starts within 0.7 px of the truth, ``default`` validation seeds 7-9 (dots
        3 mm apart, :data:`lipgen.subject.inkdots.DOT_SEPARATION_MM`) 0.37-0.55 px RMS with the
        plain fit, 0.18-0.25 px with 1.25 (a dot near the lip line was 0.8-1.7 px off). Its wrong
        sightings on ``default`` before came from a false global jump of the layout, which
        :func:`lipgen.recon.association.predict` now refuses. Calibrate, track, triangulate (plain
        -> 1.25, accepted share, sightings over 3 px both views): ``default`` seeds 7-9 90.6 ->
        91.5 % on average, 149 -> 132; hard validation seeds 7-10 36.1 -> 57.6 %, 122 -> 66 (hard
        seed 7 alone 61 -> 57 %); ``easy`` seed 7 0.17/0.16 -> 0.17/0.18 px, 100 %. Held out
        (``default`` seeds 11-13): 91.4 / 90.0 / 62.7 -> 93.6 / 93.9 / 83.6 %, over 3 px 0 / 0 /
        119 -> 30 / 0 / 59 (seed 11: ``upper_right`` on a wrong dot in both views from frame 29;
        seed 13: ``lower_corner_left``, unmatched in the first frame, acquired on a wrong dot).
    """

    sigma: float = 1.5
    min_contrast: float = 0.08
    noise_k: float = 4.5
    min_separation: float | None = None
    smoothing: float = 0.6
    min_roundness: float = 0.3
    min_foreshortened_roundness: float = 0.1
    blob_response: str = "hessian"
    window: float | None = 1.25

    def __post_init__(self) -> None:
        if not (np.isfinite(self.sigma) and 0.3 <= self.sigma <= 50):
            raise ValueError(f"DotSettings.sigma must be in [0.3, 50] pixels, got {self.sigma!r}")
        if not 0 < self.min_contrast < 1:
            raise ValueError(f"DotSettings.min_contrast must be in (0, 1), got {self.min_contrast!r}")
        if self.blob_response not in BLOB_RESPONSES:
            raise ValueError(f"DotSettings.blob_response must be one of {BLOB_RESPONSES}, "
                             f"got {self.blob_response!r}")

    @property
    def separation(self) -> float:
        return float(self.min_separation if self.min_separation is not None else 2.0 * self.sigma)


def as_gray(image) -> np.ndarray:
    """An image as a float64 grey array in [0, 1].

    Parameters
    ----------
    image : (h, w) or (h, w, 3|4) array
        uint8 (0..255), uint16, or float already in [0, 1].

    Returns
    -------
    (h, w) float
    """
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] in (3, 4):
        scale = _full_scale(img)
        rgb = img[..., :3].astype(np.float64) / scale
        return rgb @ np.array([0.299, 0.587, 0.114])
    if img.ndim != 2:
        raise ValueError(f"image must have shape (h, w) or (h, w, 3|4), got {img.shape}")
    return img.astype(np.float64) / _full_scale(img)


def ink_gray(image) -> np.ndarray:
    """An image as the grey array dots are found in: each pixel's brightest channel, in [0, 1].

    Ink is dark in every channel, while lips and skin are bright in red. In luminance the lip
    line and the mouth corners are nearly as dark against the skin as the ink is against the lip
    (54 vs 71 grey levels in our renders), so a corner's tip passes for a dot and a centroid is
    pulled toward edges; in the brightest channel they differ far more (26 vs 139). A grey image
    is returned as it is (scaled to [0, 1]). ``image`` and the result are as in :func:`as_gray`.
    """
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] in (3, 4):
        return img[..., :3].max(axis=2).astype(np.float64) / _full_scale(img)
    return as_gray(img)


def _full_scale(img: np.ndarray) -> float:
    if img.dtype == np.uint8:
        return 255.0
    if img.dtype == np.uint16:
        return 65535.0
    if not np.issubdtype(img.dtype, np.floating):
        raise TypeError(f"image dtype must be uint8, uint16 or float, got {img.dtype}")
    return 1.0


def darkness(gray: np.ndarray, sigma: float) -> np.ndarray:
    """Black top-hat: how much darker than its surroundings each pixel is, for blobs ~``sigma``.

    Returns
    -------
    (h, w) float, >= 0
    """
    radius = int(np.ceil(3.0 * sigma)) + 1
    # A square element (separable, so fast) a little wider than the dot.
    closed = ndimage.grey_closing(gray, size=(2 * radius + 1, 2 * radius + 1), mode="nearest")
    return closed - gray


def detect_dots(image, settings: DotSettings = DotSettings(), mask: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """Find dark dots and their sub-pixel centres.

    Parameters
    ----------
    image : (h, w) or (h, w, 3) array
        A grey or colour image (searched in :func:`ink_gray`).
    settings : DotSettings
    mask : (h, w) bool, optional
        Only peaks where the mask is true are kept.

    Returns
    -------
    uv : (k, 2) float
        Dot centres (column, row) in pixels, strongest first.
    strength : (k,) float
        Smoothed peak darkness of each dot (0..1 of full scale).
    """
    gray = ink_gray(image)
    peaks, strength, roundness = dot_peaks(gray, settings, mask)
    round_ = roundness >= settings.min_roundness
    uv, keep = refine_peaks(gray, peaks[round_], settings)
    return uv, strength[round_][keep]


def dot_peaks(gray: np.ndarray, settings: DotSettings = DotSettings(), mask: np.ndarray | None = None,
              response: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Whole-pixel peaks of the dot response, round ones and elongated ones (not refined).

    Parameters
    ----------
    gray : (h, w) float
    settings : DotSettings
    mask : (h, w) bool, optional
    response : (h, w) float, optional
        :func:`dot_response` of ``gray`` if the caller has it already (it is not recomputed).

    Returns
    -------
    uv : (k, 2) float
        Peak pixels (column, row), strongest first.
    strength : (k,) float
        Smoothed peak darkness.
    roundness : (k,) float
        Ratio of the weaker to the stronger principal curvature of the response at the peak
        (1 round, 0 a line); all are at least ``settings.min_foreshortened_roundness`` (or
        ``min_roundness`` if lower). :func:`detect_dots` keeps those of ``min_roundness`` or more.
    """
    if response is None:
        response = dot_response(gray, settings)
    peaks = local_maxima(response, settings, settings.min_contrast)
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        if m.shape != gray.shape:
            raise ValueError(f"mask must have the image's shape {gray.shape}, got {m.shape}")
        peaks &= m
    rows, cols = np.nonzero(peaks)
    roundness, strong = peak_roundness(response, rows, cols)
    ok = (strong < 0) & (roundness >= min(settings.min_foreshortened_roundness, settings.min_roundness))
    rows, cols, roundness = rows[ok], cols[ok], roundness[ok]
    strength = response[rows, cols]
    order = np.argsort(-strength, kind="stable")
    uv = np.column_stack([cols[order], rows[order]]).astype(np.float64)
    return uv, strength[order], roundness[order]


def dot_response(gray: np.ndarray, settings: DotSettings) -> np.ndarray:
    """(h, w) the detector's response: the top-hat :func:`darkness` smoothed by
    ``settings.smoothing * sigma`` (a matched filter)."""
    dark = darkness(gray, settings.sigma)
    return ndimage.gaussian_filter(dark, settings.smoothing * settings.sigma, mode="nearest")


def local_maxima(response: np.ndarray, settings: DotSettings, floor: float) -> np.ndarray:
    """(h, w) bool: maxima of ``response`` over a ``settings.separation`` window, above ``floor``
    and the robust noise floor (median + ``noise_k`` MADs), not within 2 sigma of the border."""
    # A robust noise floor: most pixels are not dots, so the median absolute deviation of the
    # response measures the texture and noise that a dot must stand out from.
    med = np.median(response)
    mad = 1.4826 * np.median(np.abs(response - med))
    threshold = max(floor, med + settings.noise_k * mad)
    size = 2 * int(np.floor(settings.separation / 2)) + 1
    peaks = (response == ndimage.maximum_filter(response, size=size, mode="nearest")) & (response > threshold)
    # The closing is unreliable within a dot radius of the border (it cannot see past it).
    edge = int(np.ceil(2.0 * settings.sigma))
    peaks[:edge], peaks[-edge:], peaks[:, :edge], peaks[:, -edge:] = False, False, False, False
    return peaks


def peak_roundness(response: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """At maxima (rows, cols) (k,): roundness, the weaker over the stronger principal curvature
    of ``response`` in [0, 1] (1 round, 0 a line; 0 where not a maximum), and the stronger (k,)."""
    # Round blobs: at a dot both principal curvatures of the response are strongly negative;
    # along a dark line or slit (the mouth opening, a crease) one of them is near 0. A dot seen
    # obliquely (foreshortened) lies in between.
    ryy = response[rows + 1, cols] + response[rows - 1, cols] - 2 * response[rows, cols]
    rxx = response[rows, cols + 1] + response[rows, cols - 1] - 2 * response[rows, cols]
    rxy = 0.25 * (response[rows + 1, cols + 1] + response[rows - 1, cols - 1]
                  - response[rows + 1, cols - 1] - response[rows - 1, cols + 1])
    half_trace, det_root = 0.5 * (rxx + ryy), np.sqrt(0.25 * (rxx - ryy) ** 2 + rxy ** 2)
    weak, strong = half_trace + det_root, half_trace - det_root      # eigenvalues, weak >= strong
    roundness = np.where(strong < 0, np.clip(weak / np.minimum(strong, -1e-300), 0.0, 1.0), 0.0)
    return roundness, strong


def refine_peaks(gray: np.ndarray, peaks: np.ndarray, settings: DotSettings) -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel centres of ``peaks (k, 2)`` (strongest first); returns (uv (m, 2), kept (k,) bool).

    A plateau can give two maxima a pixel apart that converge to one dot: the stronger is kept.
    Fits that end outside the image (edge artefacts of the closing) are not dots.
    """
    uv = refine_centroids(gray, peaks, settings.sigma, window=settings.window)
    h, w = gray.shape
    inside = (uv[:, 0] >= 0) & (uv[:, 0] <= w - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= h - 1)
    keep = _dedupe(uv, settings.separation / 2) & inside
    return uv[keep], keep


def _dedupe(uv: np.ndarray, radius: float) -> np.ndarray:
    keep = np.ones(len(uv), dtype=bool)
    for i in range(len(uv)):
        if keep[i]:
            close = np.linalg.norm(uv[i + 1:] - uv[i], axis=1) < radius
            keep[i + 1:][close] = False
    return keep


@single_threaded  # a stack of 10x10 solves per iteration: threads only wait (lipgen._threads)
def refine_centroids(gray: np.ndarray, uv: np.ndarray, sigma: float, iterations: int = 15,
                     deblend: int = 2, window: float | None = None) -> np.ndarray:
    """Sub-pixel dot centres by fitting a Gaussian dot on a quadratic background.

    Each patch of radius ``ceil(3 sigma) + 1`` around a starting point is fitted (batched
    Levenberg-Marquardt over all points at once) by

        I(x, y) = c0 + c1 dx + c2 dy + c3 dx^2 + c4 dx dy + c5 dy^2 - a exp(-|(x, y) - (u, v)|^2 / 2 s^2)

    so shading and texture gradients under the dot do not pull the centre, as they pull a plain
    centroid. With ``window``, the pixels are weighted by a Gaussian of ``window * sigma`` round
    the start, then round the fitted centre (a second fit), so what the model cannot follow at
    the patch's edge (the lip border, the mouth opening, a crease: steps no quadratic describes)
    has little say. With 1.25, centres started within 0.7 px of the truth (every 4th frame,
    mirror / direct px RMS): hard validation seeds 7 and 8 1.04 / 0.74 -> 0.50 / 0.49 and
    1.01 / 0.71 -> 0.53 / 0.49, ``default`` seed 7 0.50 / 0.42 -> 0.39 / 0.30, ``easy`` seed 7
    0.17 / 0.16 -> 0.16 / 0.17. (Tukey-reweighted fits on top did not help: they down-weight
    the dot's own edge, where a disc departs from a Gaussian.)
    Dots close enough to share a patch are deblended: each fit sees the image with the
    other dots' current Gaussians added back (they are dark, so they are subtracted from the
    darkness), and the fits are repeated ``deblend`` times. Without it two dots 4 px apart
    (sigma 1.3 px) both converge to their midpoint.

    Parameters
    ----------
    gray : (h, w) float
        The grey image.
    uv : (k, 2) float
        Starting points (column, row), within about a dot radius of the dots.
    sigma : float
        Expected dot radius (pixels); the fitted radius is free.
    iterations : int
        Levenberg-Marquardt steps per fit.
    deblend : int
        Extra fitting rounds for dots with a neighbour in their patch.
    window : float or None
        Radius (in ``sigma``) of the Gaussian weight window around each starting point; None:
        every pixel of the patch counts the same.

    Returns
    -------
    (k, 2) float
        Fitted centres. A fit that fails (diverges, or leaves its patch) keeps its start.
    """
    uv0 = as_float_array(uv, "uv", (None, 2)).copy()
    k = len(uv0)
    if k == 0:
        return uv0
    h, w = gray.shape
    half = int(np.ceil(3.0 * sigma)) + 1
    offs = np.arange(-half, half + 1, dtype=np.float64)
    base = np.round(uv0)
    cols = np.clip(base[:, 0, None] + offs, 0, w - 1).astype(np.int64)
    rows = np.clip(base[:, 1, None] + offs, 0, h - 1).astype(np.int64)
    img = gray[rows[:, :, None], cols[:, None, :]].reshape(k, -1)          # (k, p*p)
    dy, dx = (a.ravel() for a in np.meshgrid(offs, offs, indexing="ij"))
    bg = np.stack([np.ones_like(dx), dx, dy, dx * dx, dx * dy, dy * dy], axis=1)   # (p*p, 6)
    # Start: the dot at the start point, background and depth by linear least squares.
    u = uv0[:, 0] - base[:, 0]
    v = uv0[:, 1] - base[:, 1]
    s = np.full(k, float(sigma))
    g = np.exp(-((dx - u[:, None]) ** 2 + (dy - v[:, None]) ** 2) / (2 * s[:, None] ** 2))
    design = np.concatenate([np.broadcast_to(bg, (k, *bg.shape)), -g[:, :, None]], axis=2)
    lin = (np.linalg.pinv(design) @ img[:, :, None])[..., 0]
    params = np.column_stack([u, v, s, lin[:, 6], lin[:, :6]])              # (k, 10)
    # Pixel positions of every patch in image coordinates, for the neighbours' contributions.
    px = base[:, 0, None] + dx
    py = base[:, 1, None] + dy
    close = np.linalg.norm(uv0[:, None] - uv0[None], axis=2) < 2 * half
    np.fill_diagonal(close, False)
    weight = np.ones_like(img)
    if window is not None:
        if not (np.isfinite(window) and window > 0):
            raise ValueError(f"window must be a positive number of sigmas or None, got {window!r}")
        weight = np.exp(-((dx - u[:, None]) ** 2 + (dy - v[:, None]) ** 2) / (2 * (window * sigma) ** 2))
    params = _lm_fit(img, bg, dx, dy, params, iterations, sigma, weight)
    if window is not None:
        # The window moved to the fitted centre, and the fit repeated: the centre then depends
        # little on where the fit started (a detector's whole pixel, another view's guess).
        r2 = (dx - params[:, 0:1]) ** 2 + (dy - params[:, 1:2]) ** 2
        weight = np.exp(-r2 / (2 * (window * sigma) ** 2))
        params = _lm_fit(img, bg, dx, dy, params, iterations, sigma, weight)
    crowded = np.flatnonzero(close.any(1))
    for _ in range(deblend if len(crowded) else 0):
        others = np.zeros((len(crowded), img.shape[1]))
        cu, cv = base[:, 0] + params[:, 0], base[:, 1] + params[:, 1]
        for row, i in enumerate(crowded):
            nb = np.flatnonzero(close[i])
            r2 = (px[i] - cu[nb, None]) ** 2 + (py[i] - cv[nb, None]) ** 2
            others[row] = (np.maximum(params[nb, 3], 0.0)[:, None]
                           * np.exp(-r2 / (2 * params[nb, 2, None] ** 2))).sum(0)
        params[crowded] = _lm_fit(img[crowded] + others, bg, dx, dy, params[crowded], iterations, sigma,
                                  weight[crowded])
    out = base + params[:, :2]
    bad = (np.abs(params[:, :2]).max(1) > half - 1) | (params[:, 3] <= 0) | ~np.isfinite(out).all(1)
    out[bad] = uv0[bad]
    return out


def _lm_fit(img, bg, dx, dy, params, iterations, sigma, weight=None):
    """Batched Levenberg-Marquardt of the dot model (see :func:`refine_centroids`), each pixel's
    squared residual weighted by ``weight (k, p*p)`` (None: all 1)."""
    params = params.copy()
    wt = np.ones_like(img) if weight is None else weight

    def residual_and_jac(p):
        pu, pv, ps, pa = p[:, 0:1], p[:, 1:2], p[:, 2:3], p[:, 3:4]
        ex, ey = dx - pu, dy - pv
        r2 = ex * ex + ey * ey
        gg = np.exp(-r2 / (2 * ps * ps))
        model = p[:, 4:] @ bg.T - pa * gg
        # ps * ps * ps, not ps ** 3: numpy 1.26's AVX-512 power (SVML) falls back to libm's, 1 ulp
        # apart, when its overlap check, which overshoots a strided view's end, meets the output
        # allocated just after ``p``: the fit then depended on the heap layout (1e-8 px, run to run).
        jac = np.concatenate([
            (-pa * gg * ex / ps ** 2)[..., None], (-pa * gg * ey / ps ** 2)[..., None],
            (-pa * gg * r2 / (ps * ps * ps))[..., None], -gg[..., None],
            np.broadcast_to(bg, (len(p), *bg.shape))], axis=2)
        return model - img, jac

    lam = np.full(len(params), 1e-3)
    res, jac = residual_and_jac(params)
    cost = (wt * res * res).sum(1)
    eye = np.eye(params.shape[1])
    for _ in range(iterations):
        jt = (jac * wt[..., None]).transpose(0, 2, 1)
        jtj = jt @ jac
        jtr = (jt @ res[..., None])[..., 0]
        damp = jtj + lam[:, None, None] * (eye * np.diagonal(jtj, axis1=1, axis2=2)[:, None, :] + 1e-12 * eye)
        step = np.linalg.solve(damp, -jtr[..., None])[..., 0]
        trial = params + step
        trial[:, 2] = np.clip(trial[:, 2], 0.3, 3.0 * sigma)
        r_new, j_new = residual_and_jac(trial)
        c_new = (wt * r_new * r_new).sum(1)
        better = c_new < cost
        params[better], res[better], jac[better], cost[better] = trial[better], r_new[better], \
            j_new[better], c_new[better]
        lam = np.where(better, lam * 0.3, lam * 10.0)
    return params
