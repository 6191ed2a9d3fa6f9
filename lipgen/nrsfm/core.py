"""``reconstruct``: one entry point for every method (the engine is :mod:`.engine`, the record
:mod:`.record`, the choice of K :mod:`.kchoice`)."""

from __future__ import annotations

from lipgen._threads import single_threaded
from lipgen.nrsfm.engine import reconstruct_k
from lipgen.nrsfm.kchoice import choose_k, curve_values, reconstruct_auto
from lipgen.nrsfm.pndk import reconstruct_pnd_auto
from lipgen.nrsfm.record import (
    DEFAULT_METHOD,
    MEAN_PLUS_MODES,
    METHODS,
    Reconstruction,
    check_method_k,
    n_basis_shapes,
)

__all__ = ["Reconstruction", "reconstruct", "curve_values", "choose_k",
           "METHODS", "DEFAULT_METHOD", "MEAN_PLUS_MODES", "n_basis_shapes",
           "check_method_k"]


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
        Number of basis shapes K, or ``"auto"``: for ``"dai"`` and ``"dai-ba"`` the K whose
        rotations are smoothest in time, preferring among those the smallest K that explains
        noise-free tracks exactly (:func:`lipgen.nrsfm.kchoice.smooth_k`, kept in
        ``info["k_choice"]``); ``"dai"`` then takes as depth the mean of the 4 smoothest Ks' depths,
        shrunk towards flat by the James-Stein factor of their spread
        (:func:`lipgen.nrsfm.consensus.consensus_reconstruction`, ``info["depth_consensus"]``; an exact
        K-shape fit is kept as it is; shrinking the depth by its split-half reliability is opt-in,
        :func:`lipgen.nrsfm.kchoice.shrink_unreliable_depth`), and returns the flat answer (zero
        depth, ``Reconstruction.depth_supported`` False, the reason in ``info["depth_support"]``)
        when the even and the odd frames alone give rotations that disagree
        (:func:`lipgen.nrsfm.support.depth_support`); for the others K from the
        reprojection curve (:func:`lipgen.nrsfm.reprojection_curve`, default thresholds; kept in
        ``info["k_curve"]``). For
        ``"em-ppca"`` the number of deformation modes beyond the mean shape (K >= 0, K + 1 basis
        shapes): em-ppca with K modes spans the same rank-3(K + 1) model as ``"dai"`` with K + 1.
        ``"em-pnd"`` counts modes likewise; its ``"auto"`` is the least BIC of its own likelihood
        (:func:`lipgen.nrsfm.pndk.reconstruct_pnd_auto`, kept in ``info["k_choice"]``).
    method : str
        One of :data:`METHODS`: ``"bregler"``, ``"dai"`` (default), ``"dai-ba"``, ``"em-ppca"`` or
        ``"em-pnd"``.
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
        Iteration cap of EM (``"em-ppca"``, ``"em-pnd"``).

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
        if method == "em-pnd":
            return reconstruct_pnd_auto(W, visible, **options)
        return reconstruct_auto(W, method, visible, **options)
    return reconstruct_k(W, k, method, visible, **options)
