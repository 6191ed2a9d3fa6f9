"""The field's 3D error (e3D, after Akhter et al.) and the choice of K from the reprojection curve."""

from __future__ import annotations

import contextlib
import logging
from dataclasses import dataclass

import numpy as np

from lipgen._validate import as_float_array
from lipgen.nrsfm.kchoice import choose_k, curve_values
from lipgen.nrsfm.record import DEFAULT_METHOD, MEAN_PLUS_MODES

__all__ = ["e3d", "flat_e3d", "KCurve", "reprojection_curve", "choose_k", "plot_curve", "plot_k_choice"]

log = logging.getLogger(__name__)


def _as_stacked(S, name: str) -> np.ndarray:
    S = as_float_array(S, name)
    if S.ndim == 3 and S.shape[1] == 3:
        return S.reshape(-1, S.shape[2])
    if S.ndim != 2 or S.shape[0] % 3:
        raise ValueError(f"{name} must be (3F, P) with rows x1, y1, z1, x2, ... or (F, 3, P), got shape "
                         f"{S.shape}")
    return S


def e3d(*args, S_est=None, S_true=None) -> float:
    """Normalised mean 3D error of a shape sequence, as the benchmark defines it.

    Keyword arguments only, ``e3d(S_est=..., S_true=...)``: the error is not symmetric (``s``
    comes from the truth), and the benchmark README names the truth first where this function
    used to take the estimate first, so a positional call is refused rather than guessed.

    1. ``s`` = mean over the 3F rows of ``S_true`` of the population std across points.
    2. Both sequences are divided by ``s`` and each row is centred.
    3. One 3 x 3 orthogonal matrix (reflection allowed) aligns all frames of the estimate to the
       truth (orthogonal Procrustes).
    4. Per frame, the mean over points of the Euclidean distance; e3D is the mean over frames.

    Parameters
    ----------
    S_est, S_true : (3F, P) or (F, 3, P) array_like
        Camera-frame shapes, rows x1, y1, z1, x2, ...

    Returns
    -------
    float
        Invariant to one global rotation or reflection of the estimate, and to scaling both
        inputs together; 0 for identical inputs.
    """
    if args:
        raise TypeError(f"e3d takes keyword arguments only, e3d(S_est=..., S_true=...); got {len(args)} "
                        "positional argument(s) (the order of estimate and truth matters)")
    if S_est is None or S_true is None:
        raise TypeError("e3d needs both S_est= (the estimate) and S_true= (the ground truth)")
    A = _as_stacked(S_est, "S_est")
    B = _as_stacked(S_true, "S_true")
    if A.shape != B.shape:
        raise ValueError(f"S_est and S_true must have the same shape, got {A.shape} and {B.shape}")
    top = float(np.abs(B).max())
    if top > 0:  # an exact power-of-two rescale first, so that squares neither overflow nor underflow
        p2 = 2.0 ** np.round(np.log2(top))
        A, B = A / p2, B / p2
    s = float(np.mean(np.std(B, axis=1)))
    if not s > 0:
        raise ValueError(f"S_true of shape {B.shape} is constant within every row: e3D is undefined")
    A = A / s
    B = B / s
    A = A - A.mean(axis=1, keepdims=True)
    B = B - B.mean(axis=1, keepdims=True)
    F = A.shape[0] // 3
    a, b = A.reshape(F, 3, -1), B.reshape(F, 3, -1)
    U, _, Vt = np.linalg.svd(np.einsum("fip,fjp->ij", b, a))
    Q = U @ Vt  # orthogonal, det +-1: maps the estimate onto the truth
    dist = np.linalg.norm(np.einsum("ij,fjp->fip", Q, a) - b, axis=1)
    return float(dist.mean(axis=1).mean())


@dataclass(frozen=True)
class KCurve:
    """Reprojection error against the number of basis shapes (Bregler et al. 1999, Fig 2).

    Attributes
    ----------
    ks : (n,) int
    rms : (n,) float
        RMS reprojection error over observed coordinates, in the units of W.
    relative : (n,) float
        ``rms`` divided by the RMS of the centred observed tracks.
    chosen : int
        K picked by :func:`choose_k`.
    rule : str
        The rule, in words, with its thresholds.
    method : str
    """

    ks: np.ndarray
    rms: np.ndarray
    relative: np.ndarray
    chosen: int
    rule: str
    method: str


def flat_e3d(W, S_true, fill=None) -> float:
    """e3D of the flat baseline: the tracks with zero depth, what no reconstruction at all scores.

    Parameters
    ----------
    W : (2F, P) array_like
        Tracks, rows u1, v1, u2, v2, ...; NaN where a point was not seen.
    S_true : (3F, P) or (F, 3, P) array_like
        The true camera-frame shapes.
    fill : (2F, P) array_like, optional
        What the baseline puts where ``W`` is NaN (e.g. the truth's projections); needed when ``W``
        has NaN.

    Returns
    -------
    float
        :func:`e3d` of the shapes ``(u, v, 0)`` (each row centred) against ``S_true``.
    """
    W = np.asarray(W, dtype=np.float64)
    if W.ndim != 2 or W.shape[0] % 2:
        raise ValueError(f"W must be (2F, P) tracks, got shape {W.shape}")
    if fill is not None:
        fill = np.asarray(fill, dtype=np.float64)
        if fill.shape != W.shape:
            raise ValueError(f"fill must have W's shape {W.shape}, got {fill.shape}")
        W = np.where(np.isfinite(W), W, fill)
    if not np.isfinite(W).all():
        raise ValueError(f"W has {int((~np.isfinite(W)).sum())} missing entries and no fill: give fill= "
                         "(e.g. the truth's projections) for the flat baseline")
    F, P = W.shape[0] // 2, W.shape[1]
    flat = np.zeros((F, 3, P))
    flat[:, :2] = (W - W.mean(1, keepdims=True)).reshape(F, 2, P)
    return e3d(S_est=flat, S_true=S_true)


def reprojection_curve(W, ks=None, method: str = DEFAULT_METHOD, visible=None, rtol: float = 0.01,
                       flat: float = 0.05, progress: bool = False, **options) -> KCurve:
    """Reconstruct with K = 1, 2, ... and record the reprojection error; choose K by :func:`choose_k`.

    Parameters
    ----------
    W : (2F, P) array_like
    ks : iterable of int, optional
        Ks to try; by default 1 up to the largest K the data allow, at most 15 (for ``"em-ppca"``,
        whose K counts modes beyond the mean shape, 0 up to one less).
    method : str
        Method whose reprojection is measured (see :data:`lipgen.nrsfm.METHODS`).
    visible : (F, P) array_like of bool, optional
    rtol, flat : float
        Thresholds of the rule (see :func:`choose_k`).
    progress : bool
        Show a progress bar.
    **options
        Passed to :func:`lipgen.nrsfm.reconstruct`.
    """
    ks, rms, relative = curve_values(W, ks, method, visible, progress, **options)
    chosen, rule = choose_k(ks, relative, rtol=rtol, flat=flat)
    return KCurve(ks=ks, rms=rms, relative=relative, chosen=chosen, rule=rule, method=method)


@contextlib.contextmanager
def _figure(path, title: str, xlabel: str, ylabel: str):
    """A (5.5 x 3.6 in) Agg figure's axes; on leaving, grid, legend and labels are set and the figure
    is written to ``path`` atomically, then closed (also on error)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lipgen._io import atomic_savefig

    fig, ax = plt.subplots(figsize=(5.5, 3.6), dpi=120)
    try:
        yield ax
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.set_title(title, fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        atomic_savefig(fig, path)
    finally:
        plt.close(fig)


def plot_curve(curve: KCurve, path) -> None:
    """Write the reprojection curve (log scale) with the chosen K marked, atomically (Agg)."""
    xlabel = ("deformation modes K (beyond the mean shape)" if curve.method in MEAN_PLUS_MODES
              else "number of basis shapes K")
    with _figure(path, "Reprojection error against K (Bregler et al. Fig 2)", xlabel,
                 "RMS reprojection error (% of track RMS)") as ax:
        ax.semilogy(curve.ks, 100 * curve.relative, "o-", color="tab:blue", label=curve.method)
        i = int(np.flatnonzero(curve.ks == curve.chosen)[0])
        ax.semilogy([curve.chosen], [100 * curve.relative[i]], "s", ms=11, mfc="none", color="tab:red",
                    label=f"chosen K = {curve.chosen}")


def plot_k_choice(choice: dict, path) -> None:
    """Write the rotation roughness per K (``info["k_choice"]`` of ``reconstruct(W, "auto")``),
    log scale, the chosen K marked and exact K-shape fits ringed, atomically (Agg).

    Parameters
    ----------
    choice : dict
        ``ks``, ``rotation_roughness``, ``exact``, ``chosen`` (lists per K and the chosen K).
    path : str or Path
    """
    ks = np.asarray(choice["ks"])
    rough = np.maximum(np.asarray(choice["rotation_roughness"], float), 1e-300)
    exact = np.asarray(choice["exact"], bool)
    with _figure(path, "Smoothness of the recovered rotations against K", "number of basis shapes K",
                 "rotation roughness (mean |R''|^2)") as ax:
        ax.semilogy(ks, rough, "o-", color="tab:blue", label="dai")
        if exact.any():
            ax.semilogy(ks[exact], rough[exact], "o", ms=9, mfc="none", color="tab:green",
                        label="exact K-shape fit")
        i = int(np.flatnonzero(ks == choice["chosen"])[0])
        ax.semilogy([ks[i]], [rough[i]], "s", ms=11, mfc="none", color="tab:red",
                    label=f"chosen K = {choice['chosen']}")
