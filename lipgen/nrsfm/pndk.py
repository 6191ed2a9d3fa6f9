"""``k="auto"`` for ``method="em-pnd"``: the number of deformation modes by the Bayesian information
criterion of EM-PND's marginal likelihood (no truth, no user parameter).

EM-PND is a probabilistic model, so its own evidence can choose K: for each K on a grid
(:data:`K_GRID`, up to what the tracks allow), the fit's marginal negative log-likelihood plus
half its number of free parameters times the log of the number of observed coordinates
(:func:`lipgen.nrsfm.empnd.bic`). Among the fits that EM-PND kept (plausible against their
``dai`` start, see :func:`lipgen.nrsfm.empnd.pnd_reconstruction`), the least criterion wins; if
none was kept, the least criterion overall (whose answer is then its ``dai`` start). Noise-free
low-rank tracks come first: the smallest K whose answer reproduces them exactly wins (their
likelihood is unbounded, so the criterion cannot rank them).
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen._threads import single_threaded
from lipgen.nrsfm._tracks import check_tracks
from lipgen.nrsfm.empnd import bic
from lipgen.nrsfm.engine import at_unit_scale, reconstruct_k
from lipgen.nrsfm.kchoice import candidate_ks
from lipgen.nrsfm.record import Reconstruction

__all__ = ["K_GRID", "EXACT_REPROJECTION", "reconstruct_pnd_auto"]

log = logging.getLogger(__name__)

EXACT_REPROJECTION = 1e-6
"""RMS reprojection, relative to the largest track coordinate, below which a fit reproduces the
tracks exactly (noise-free low-rank tracks)."""

K_GRID = (0, 1, 2, 4, 8, 12)
"""Numbers of deformation modes tried by ``k="auto"`` (those the tracks allow)."""


@single_threaded(always=True)
@at_unit_scale
def reconstruct_pnd_auto(W, visible=None, *, kmax: int = 12, **options) -> Reconstruction:
    """:func:`lipgen.nrsfm.reconstruct` with ``method="em-pnd"`` and ``k="auto"``.

    Parameters
    ----------
    W : (2F, P) array_like
    visible : (F, P) array_like of bool, optional
    kmax : int
        Largest number of modes tried.
    **options
        As :func:`lipgen.nrsfm.reconstruct`.

    Returns
    -------
    Reconstruction
        The chosen fit; ``info["k_choice"]`` holds ``ks``, ``bic``, ``kept``, ``exact`` (lists per K),
        ``chosen`` and ``rule``.
    """
    tracks = check_tracks(W, visible)
    F, P = tracks.mask.shape
    allowed = set(candidate_ks(F, P, tracks.n_observed, "em-pnd", kmax))
    ks = [k for k in K_GRID if k in allowed and k <= kmax]
    if not ks:  # no K fits: let the engine give its message for K = 0
        return reconstruct_k(W, 0, "em-pnd", visible, **options)
    runs, scores, kept = [], [], []
    for k in ks:
        rec = reconstruct_k(W, k, "em-pnd", visible, **options)
        # the criterion in the units of the normalised tracks (reconstruct_k's exact power-of-two scale)
        runs.append(rec)
        scores.append(bic(rec.info["nll_total"], k, F, P, 2 * tracks.n_observed))
        kept.append(bool(rec.info["pnd_kept"]))
        log.info("em-pnd K=%d: BIC %.6g, kept %s", k, scores[-1], kept[-1])
    # noise-free low-rank tracks: the smallest K whose answer reproduces them exactly (infinite
    # likelihood; dai's exact K-shape fit when EM-PND was not kept)
    size = float(np.abs(tracks.W).max())
    exact = [r.reprojection_rms <= EXACT_REPROJECTION * size for r in runs]
    pool = [i for i in range(len(ks)) if kept[i]] or list(range(len(ks)))
    best = exact.index(True) if any(exact) else min(pool, key=lambda i: scores[i])
    rec = runs[best]
    rec.info["k_choice"] = {"ks": ks, "bic": scores, "kept": kept, "exact": exact, "chosen": ks[best],
                            "rule": "the smallest K reproducing the tracks exactly, else the least BIC of "
                                    "EM-PND's marginal likelihood among the plausible fits"}
    return rec
