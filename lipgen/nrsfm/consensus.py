"""Depth by consensus of the smoothest Ks, shrunk by how much they disagree: the last step of
``k="auto"`` for ``dai``.

``k="auto"`` runs ``dai`` at every K (:mod:`lipgen.nrsfm.kchoice`) and keeps one. Under orthography
the image gives x and y; only the camera-frame depth is inferred, and on short or weakly rotating
sequences it can be wrong enough that the flat answer (zero depth) is closer to the truth. The
reconstructions at the Ks whose rotations are smoothest are several estimates of the same depth, and
their errors differ from K to K (after Lee et al., "Consensus of non-rigid reconstructions", CVPR
2016: parts that many reconstructions agree on are the reliable ones). :func:`consensus_depth` takes
the :data:`CONSENSUS_KS` smoothest Ks (always with the chosen one), aligns each depth's sign (a
global reflection) with the chosen K's, and averages them: depth they agree on is kept, depth they
do not agree on partly cancels.

The mean is then shrunk towards zero by the positive-part James-Stein factor
``a = max(0, 1 - (s2 / m) / |zbar|^2)``: ``zbar`` the mean depth (all frames and points), ``s2`` the
summed squared spread of the ``m`` depths about it over ``m - 1``, so ``s2 / m`` estimates the noise
left in the mean and ``a`` the signal over signal plus noise. The spread of reconstructions of the same
tracks underestimates their error (they share the data), so ``a`` errs towards keeping the depth.

An exact K-shape fit (``info["shapes"] == "rank-K fit"``: noise-free tracks explained exactly, as jaws
at K = 3) is kept as it is: other Ks are not estimates of the same shapes there.

The rule (4 smoothest Ks, mean, James-Stein factor) was chosen on development bodies of
:mod:`lipgen.nrsfm.validation` (seeds 300-307, 400, 405-407 and 900-903, 80 frames) against the
split-half reliability (:mod:`lipgen.nrsfm.reliability`), a cross-K regression slope and constant
factors, never on drink, jaws or the fresh seeds (there: worse than flat 5 -> 3 of 16, mean e3D
0.386 -> 0.364). Run once on fresh seeds 1000-1019 (80 frames) after it was frozen: worse than flat
3 -> 1 of 20 (dance-1014: 0.562 against flat 0.558), mean e3D 0.322 -> 0.321, median 0.321 -> 0.333;
it helped 10 bodies and hurt 10 (walk-1000: 0.115 -> 0.218), so it trades accuracy on good sequences
for fewer failures (``renders/examples/nrsfm/fresh_1000_1019.md``). ``consensus=1`` in
:func:`lipgen.nrsfm.kchoice.reconstruct_auto` keeps the chosen K's own depth.

The Ks' errors are not independent, so ``s2 / m`` understates the noise left in their mean;
:func:`design_effect` scales it for an assumed correlation ``rho`` of the errors (Kish's design effect).
It stays opt-in (``rho`` 0 by default: the factor above, bit for bit): on 17 development bodies (1000,
1005, 1006, 1009, 1014, 1102, 1105, 1106, 1113, 1116, 1206, 1209, 1210, 1302, 1305, 1310, 1318; 80
frames, with the depth-support test) ``rho`` 0.1 and 0.2 took the bodies worse than flat from 3 to 2
(only dance-1310 crossed, by 0.006) while hurting 4 and 5 more good bodies by over 0.01 (walk-1000
0.218 -> 0.240 and 0.270); mean e3D 0.460 -> 0.464 and 0.469. Where ``dai`` fails, its Ks agree on the
wrong depth (walk-1116: factor 0.90, halves 3.5 degrees apart): a bias that no spread of the Ks sees
(``renders/examples/nrsfm/fresh_1400_1419.md``).

``roughness_ratio`` (opt-in) leaves out of the mean the Ks whose rotations are far rougher than the
smoothest: on the lip views of rendered datasets the rigid K = 1 is often tens to hundreds of times
smoother than K = 2-4, and the consensus can then land on the wrong side of flat. Ratio 5, chosen on
development lip views and bodies, left no held-out sequence worse than flat (40 lip views: main 2; 20
fresh bodies, 12 CMU clips, drink, jaws: 0 either way) but raised the held-out lip views' mean e3D
0.4357 -> 0.4434 (bodies 0.3258 -> 0.3265), which its pre-registered rule forbade
(``renders/examples/nrsfm/lips_consensus_19l.md``). On a second fresh set, under a rule that put the
count worse than flat first, it left 5 of 60 worse than flat against main's 4 (``flat29.md``), so it
stays off.
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from lipgen.nrsfm.engine import _as_basis
from lipgen.nrsfm.plausibility import rotation_roughness
from lipgen.nrsfm.record import Reconstruction

__all__ = ["CONSENSUS_KS", "ERROR_CORRELATION", "design_effect", "check_rho", "check_roughness_ratio",
           "consensus_depth", "with_depth", "consensus_reconstruction"]

log = logging.getLogger(__name__)

CONSENSUS_KS = 4
"""How many of the smoothest Ks' depths are averaged (3, 4, 5 and 6 were tried on the development
bodies: 4 left the fewest sequences worse than flat and hurt the fewest)."""


ERROR_CORRELATION = 0.0
"""Assumed correlation of the averaged Ks' depth errors (they come from the same tracks), which sets the
James-Stein factor's noise through :func:`design_effect` (0: independent errors, the factor as first
built)."""


def design_effect(m: int, rho: float) -> float:
    """How much the noise left in the mean of ``m`` estimates exceeds ``s2 / m`` when their errors are
    pairwise correlated by ``rho``.

    With errors of variance ``v`` and correlation ``rho``, the spread about their mean has expectation
    ``s2 = (1 - rho) v`` and the mean's error variance is ``(1 + (m - 1) rho) v / m`` (Kish's design
    effect of correlated replicates), so the noise is ``design_effect * s2 / m`` with
    ``design_effect = (1 + (m - 1) rho) / (1 - rho)``.

    Parameters
    ----------
    m : int
        Number of estimates averaged (at least 2: one estimate has no spread).
    rho : float
        In [0, 1).

    Returns
    -------
    float
        1 for independent errors; grows without bound as ``rho`` nears 1.
    """
    if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or m < 2:
        raise ValueError(f"m must be an integer of at least 2 (estimates averaged), got {m!r}")
    check_rho(rho)
    if rho == 0:
        return 1.0
    return (1.0 + (m - 1) * float(rho)) / (1.0 - float(rho))


def check_roughness_ratio(ratio) -> None:
    """Refuse a ``roughness_ratio`` that is not None or a number >= 1 (ValueError naming it)."""
    if ratio is None:
        return
    if isinstance(ratio, bool) or not isinstance(ratio, (int, float, np.integer, np.floating)) \
            or not ratio >= 1:
        raise ValueError(f"roughness_ratio must be None or a number >= 1 (a multiple of the least "
                         f"rotation roughness), got {ratio!r}")


def check_rho(rho) -> None:
    """``ValueError`` naming ``rho`` unless it is a correlation in [0, 1) (a bool is refused)."""
    if isinstance(rho, bool) or not isinstance(rho, (int, float, np.integer, np.floating)) \
            or not 0.0 <= float(rho) < 1.0:
        raise ValueError(f"rho must be a correlation in [0, 1), got {rho!r}")


def _centred_depth(rec: Reconstruction) -> np.ndarray:
    z = rec.shapes[:, 2]
    return z - z.mean(axis=1, keepdims=True)


def consensus_depth(candidates: list[Reconstruction], chosen: int,
                    m: int = CONSENSUS_KS, rho: float = ERROR_CORRELATION,
                    roughness_ratio: float | None = None) -> tuple[np.ndarray, dict]:
    """The shrunk mean depth of the ``m`` smoothest reconstructions (see the module docstring).

    Parameters
    ----------
    candidates : list of Reconstruction
        ``dai`` at several K on the same tracks (F frames, P points).
    chosen : int
        Index into ``candidates`` of the K that was chosen; always among the averaged ones, and the
        reference of the depths' signs.
    m : int
        Number of depths averaged (at least 1; 1 returns the chosen depth, unshrunk; fewer
        candidates than ``m``: all of them).
    rho : float
        Assumed correlation of the depths' errors, in [0, 1): the noise is :func:`design_effect` times
        ``s2 / m`` (default :data:`ERROR_CORRELATION`).
    roughness_ratio : float, optional
        Leave out candidates whose rotation roughness exceeds this multiple of the least (the chosen
        one always stays). Default None: the ``m`` smoothest, however rough (see the module docstring
        for what 5 did on held-out data).

    Returns
    -------
    z : (F, P) float
        Camera-frame depth, centred in each frame.
    record : dict
        ``ks`` (averaged), ``factor`` (the James-Stein factor), ``spread`` (``s2 / m`` over ``|zbar|^2``),
        ``design_effect``.
    """
    if not candidates:
        raise ValueError("consensus_depth needs at least one reconstruction")
    if not 0 <= chosen < len(candidates):
        raise ValueError(f"chosen must index the {len(candidates)} candidates, got {chosen}")
    if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or m < 1:
        raise ValueError(f"m must be a positive integer, got {m!r}")
    shapes = {c.shapes.shape for c in candidates}
    if len(shapes) != 1:
        raise ValueError(f"the candidates' shapes differ: {sorted(shapes)}; give reconstructions of one "
                         "sequence")
    check_rho(rho)
    check_roughness_ratio(roughness_ratio)
    ratio = None if roughness_ratio is None else float(roughness_ratio)
    rough = np.array([rotation_roughness(c.rotations) for c in candidates])
    everyone = ratio is None or np.isinf(ratio)   # inf: no filter (inf * 0 would drop all but the chosen)
    order = [int(i) for i in np.argsort(rough, kind="stable") if i != chosen
             and (everyone or rough[i] <= ratio * rough.min())]
    picked = [chosen] + order[: int(m) - 1]
    effect = design_effect(len(picked), rho) if len(picked) > 1 else 1.0
    ref = _centred_depth(candidates[chosen])
    Z = []
    for i in picked:
        z = _centred_depth(candidates[i])
        Z.append(z if float(np.sum(z * ref)) >= 0 else -z)
    Z = np.stack(Z)
    zbar = Z.mean(axis=0)
    power = float(np.sum(zbar**2))
    if len(picked) == 1 or power == 0.0:
        spread, factor = 0.0, 1.0
    else:
        spread = float(np.sum((Z - zbar) ** 2)) / (len(picked) - 1) / len(picked) / power
        factor = max(0.0, 1.0 - effect * spread)
    ks = [int(candidates[i].k) for i in picked]
    log.info("consensus depth of K = %s: James-Stein factor %.3f", ks, factor)
    return factor * zbar, {"ks": ks, "factor": factor, "spread": spread, "design_effect": effect,
                           "roughness_ratio": ratio}


def with_depth(rec: Reconstruction, z: np.ndarray, info: dict | None = None) -> Reconstruction:
    """``rec`` with its camera-frame depth replaced by ``z`` (x, y, rotations and translations kept).

    Parameters
    ----------
    rec : Reconstruction
    z : (F, P) array_like
        New camera-frame depth; each frame's mean depth of ``rec`` is kept.
    info : dict, optional
        Merged into ``rec.info``.

    Returns
    -------
    Reconstruction
        The new object-frame shapes ``R_f^T S_f`` as weights (F, r) times basis (r, 3, P), r their
        numerical rank (as Dai's trace-norm shapes).
    """
    cam = rec.shapes.copy()
    z = np.asarray(z, dtype=np.float64)
    if z.shape != cam[:, 2].shape:
        raise ValueError(f"z must be (F, P) = {cam[:, 2].shape}, got shape {z.shape}")
    cam[:, 2] = z + cam[:, 2].mean(axis=1, keepdims=True)
    obj = np.einsum("fji,fjp->fip", rec.rotations, cam)          # R_f^T S_f
    weights, basis = _as_basis(obj)
    return Reconstruction(rotations=rec.rotations, weights=weights, basis=basis,
                          translation=rec.translation, method=rec.method, k=rec.k,
                          reprojection_rms=rec.reprojection_rms, info=rec.info | (info or {}))


def consensus_reconstruction(candidates: list[Reconstruction], chosen: int,
                             m: int = CONSENSUS_KS, rho: float = ERROR_CORRELATION,
                             roughness_ratio: float | None = None) -> Reconstruction:
    """The chosen reconstruction with the consensus depth (:func:`consensus_depth`), or itself when it is
    an exact K-shape fit or ``m`` is 1.

    Parameters
    ----------
    candidates : list of Reconstruction
    chosen : int
    m : int
    rho : float
    roughness_ratio : float, optional
        As :func:`consensus_depth`.

    Returns
    -------
    Reconstruction
        With ``info["depth_consensus"]`` (``ks``, ``factor``, ``spread``, ``reason``).
    """
    rec = candidates[chosen]
    if rec.info.get("shapes") == "rank-K fit" or m == 1:
        reason = "exact K-shape fit: depth kept" if m != 1 else "m = 1: depth kept"
        check_rho(rho)
        check_roughness_ratio(roughness_ratio)
        record = {"ks": [int(rec.k)], "factor": 1.0, "spread": 0.0, "design_effect": 1.0,
                  "roughness_ratio": None if roughness_ratio is None else float(roughness_ratio),
                  "reason": reason}
        return replace(rec, info=rec.info | {"depth_consensus": record})   # the same arrays, bit for bit
    z, record = consensus_depth(candidates, chosen, m, rho, roughness_ratio)
    return with_depth(rec, z, {"depth_consensus": record | {"reason": f"mean of the {len(record['ks'])} "
                                                                      "smoothest Ks, James-Stein shrunk"}})
