"""Whether the data determine the rotations (and so the depth), without the truth; flat when they do not.

Under orthography the image gives x and y; depth comes only from the rotations. ``dai``'s rotations
are one corrective triple of the rank-3K factor (:mod:`lipgen.nrsfm._rotation`), and when the tracks
do not pin it down (a body turning slowly while its limbs move much, so that deformation and
rotation explain the same image motion) the triple that wins is one of several that fit about as
well: its rotations are wrong, and so is every frame's depth, whatever K or consensus follows. On
development bodies where ``dai`` was worse than flat (1102, 1106, 1116) the relative rotations were
19-25 degrees from the truth's, against 0.5 on good bodies, and per-frame depth was unrelated to the
truth.

What the data determine, each half of the data determines too. :func:`rotation_stability` splits the
sequence into its even and its odd frames and finds each half's rotations on its own (``dai``'s first
stage at the same K, from the same starts). Each half's rotations are defined up to one rotation or
reflection of the object frame and a sign per frame (:func:`lipgen.nrsfm._rotation.orient_frames`);
the even half's rotations halfway between frames 2i and 2i + 2 are compared with the odd half's at
frame 2i + 1, after the best such alignment (:func:`rotation_disagreement`). On drink and jaws the
halves agree to 0.01 degrees. But 40 frames determine far less than 80: on the 57 development bodies
(80 frames) the halves disagreed by more than 20 degrees on 18, of which 16 were reconstructed well.

So a second test asks the whole sequence: :func:`rival_minimum` runs the corrective triple from 12
more seeded random starts and looks for a triple that reaches at most :data:`RIVAL_COST` times the
chosen cost with rotations more than :data:`RIVAL_DEG` degrees away. Many good bodies have such
rivals too (the chosen triple, started from the rigid guess, is often not the lowest minimum and
still the right one), so neither test alone separates.

:func:`depth_support` calls the depth unsupported when both hold: the halves disagree by more than
:data:`SUPPORT_DEG` degrees and a rival exists. :func:`flat_answer` is the fallback: the same
rotations, translations and image (x, y), zero depth in every frame, the result's
``info["depth_support"]`` saying so and why (``Reconstruction.depth_supported``).

Chosen on 57 development bodies of 1000-1019, 1100-1119 and 1200-1219 (80 frames; K as ``dai`` with
``k="auto"`` chose it; truth used only to score), never on drink, jaws or a fresh body, then checked
on the 3 left out by a slip in parsing (1005, 1014, 1015), unchanged. Of the 60, four were worse than
flat (1014, 1102, 1106 a tie, 1116). The rule flags 6: 1014 (0.562 -> flat 0.558), 1102 (0.517 ->
0.470), 1106 (0.613, a tie), and three good ones, 1005 (0.393 -> 0.490), 1206 (0.270 -> 0.522) and
1210 (0.432 -> 0.500); worse than flat 4 -> 1, mean e3D 0.334 -> 0.340. It does not catch 1116
(walk, 1 degree per frame: the halves agree to 3.5 degrees, the rotations are 6 degrees off).
Thresholds of 20 degrees, or a rival within 2 times the cost, flag 3-5 more good bodies. Cost: the
halves' corrective triples (0.07 s on drink, 0.1-4 s on an 80-frame body); the rival search (up to
11 s) only where the halves disagree by more than 30 degrees.
"""

from __future__ import annotations

import logging

import numpy as np

from lipgen._threads import single_threaded
from lipgen.nrsfm._rotation import complete_rotations
from lipgen.nrsfm._tracks import check_tracks
from lipgen.nrsfm.record import Reconstruction, check_method_k

__all__ = ["SUPPORT_DEG", "RIVAL_STARTS", "RIVAL_COST", "RIVAL_DEG", "MIN_HALF_FRAMES",
           "rotation_disagreement", "view_spread", "rotation_stability", "rival_minimum", "depth_support",
           "flat_answer"]

log = logging.getLogger(__name__)

SUPPORT_DEG = 30.0
"""Largest median disagreement (degrees) of the even and odd halves' rotations for which the depth
counts as supported without looking further (see :func:`depth_support`)."""

RIVAL_STARTS = 12
"""Seeded random starts of the search for a rival corrective triple (:func:`rival_minimum`)."""

RIVAL_COST = 1.3
"""A rival triple's cost, at most this multiple of the chosen triple's, counts as fitting as well."""

RIVAL_DEG = 5.0
"""A rival triple's rotations differ from the chosen ones when their median disagreement exceeds this."""

MIN_HALF_FRAMES = 8
"""Fewest frames in each half for the test; shorter sequences are not tested (depth kept)."""

_INITS = 8
"""Random starts (besides the identity) of the alignment of two rotation sequences."""


def rotation_disagreement(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Per-frame angle between two estimates of one sequence's rotations, after the best alignment.

    Each estimate is defined up to an orthogonal transform Q of the object frame (a rotation or a
    reflection: ``R_f -> R_f Q``) and a sign per frame (``R_f -> diag(-1, -1, 1) R_f``): Q and the
    signs that bring ``A``'s rows nearest ``B``'s are found by alternating Procrustes and sign
    steps from the identity and from seeded random starts (deterministic), the best kept.

    Parameters
    ----------
    A, B : (F, 3, 3) or (F, 2, 3) float
        Rotations (only the first two rows, the orthographic projection, are used).

    Returns
    -------
    (F,) float
        Angle in degrees between each frame's aligned rotation from ``A`` and its rotation from ``B``.
    """
    A = np.asarray(A, dtype=np.float64)
    B = np.asarray(B, dtype=np.float64)
    if A.ndim != 3 or A.shape[1:] not in ((3, 3), (2, 3)) or A.shape[0] != B.shape[0] \
            or B.shape[1:] not in ((3, 3), (2, 3)):
        raise ValueError(f"A and B must be (F, 3, 3) or (F, 2, 3) rotations of the same F frames, got "
                         f"shapes {A.shape} and {B.shape}")
    A2, B2 = A[:, :2], B[:, :2]
    rng = np.random.default_rng(0)
    starts = [np.eye(3)] + [np.linalg.qr(rng.standard_normal((3, 3)))[0] for _ in range(_INITS)]
    best = None
    for Q in starts:
        for _ in range(100):
            sign = _signs(np.einsum("fij,jk->fik", A2, Q), B2)
            U, _, Vt = np.linalg.svd(np.einsum("f,fji,fjk->ik", sign, A2, B2))
            new = U @ Vt
            done = bool(np.abs(new - Q).max() <= 1e-12)
            Q = new
            if done:
                break
        AQ = np.einsum("fij,jk->fik", A2, Q)
        sign = _signs(AQ, B2)
        err = float(np.sum((sign[:, None, None] * AQ - B2) ** 2))
        if best is None or err < best[0]:
            best = (err, sign[:, None, None] * AQ)
    RA, RB = complete_rotations(best[1]), complete_rotations(B2)
    # |RA - RB|_F = 2 sqrt(2) sin(angle / 2): accurate near 0, where arccos of the trace is not
    chord = np.sqrt(np.sum((RA - RB) ** 2, axis=(1, 2))) / (2.0 * np.sqrt(2.0))
    return np.degrees(2.0 * np.arcsin(np.clip(chord, 0.0, 1.0)))


def view_spread(R: np.ndarray) -> float:
    """How much the view direction varies over a sequence: the median angle (degrees) between each
    frame's view direction (third row of ``R``, the same for both per-frame signs) and their principal
    axis (a line: the nearer of its two directions).

    Parameters
    ----------
    R : (F, 3, 3) float
        Rotations.

    Returns
    -------
    float
        0 for a camera that does not turn; about 45-55 for views all around an axis.
    """
    R = np.asarray(R, dtype=np.float64)
    if R.ndim != 3 or R.shape[1:] != (3, 3):
        raise ValueError(f"R must be (F, 3, 3) rotations, got shape {R.shape}")
    n = R[:, 2]
    axis = np.linalg.eigh(n.T @ n)[1][:, -1]
    return float(np.median(np.degrees(np.arccos(np.clip(np.abs(n @ axis), 0.0, 1.0)))))


def _signs(AQ: np.ndarray, B2: np.ndarray) -> np.ndarray:
    sign = np.sign(np.einsum("fij,fij->f", AQ, B2))
    sign[sign == 0] = 1.0
    return sign


def _midpoints(R: np.ndarray) -> np.ndarray:
    """Rotations halfway between consecutive frames of ``R`` (F, 3, 3) -> (F - 1, 3, 3): each frame's
    sign is first made continuous with the frame before, then the two frames' rows are averaged and
    made orthonormal again (:func:`lipgen.nrsfm._rotation.nearest_orthonormal_rows`)."""
    from lipgen.nrsfm._rotation import nearest_orthonormal_rows

    R2 = np.array(R[:, :2], dtype=np.float64)
    for f in range(1, len(R2)):
        if float(np.sum(R2[f] * R2[f - 1])) < 0:
            R2[f] = -R2[f]
    mid, _ = nearest_orthonormal_rows(R2[1:] + R2[:-1])
    return complete_rotations(mid)


def _half_k(k: int, n_frames: int, n_points: int, mask: np.ndarray) -> int:
    """The largest K <= k that both halves accept (0 if none)."""
    for kk in range(int(k), 0, -1):
        try:
            for start in (0, 1):
                check_method_k(kk, "dai", len(range(start, n_frames, 2)), n_points,
                               int(mask[start::2].sum()))
            return kk
        except ValueError:
            continue
    return 0


@single_threaded(always=True)   # the halves' corrective triples, as reconstruct's: one BLAS thread
def rotation_stability(W, k: int, visible=None, *, seed: int = 0, n_starts: int = 4,
                       start=None) -> tuple[float, dict]:
    """Median disagreement (degrees) of the rotations found from the even and from the odd frames alone.

    Parameters
    ----------
    W : (2F, P) array_like
        Tracks, rows u1, v1, u2, v2, ... (divided by a power of two near their largest magnitude
        first, as ``dai`` does: :func:`lipgen.nrsfm.engine._normalise_scale`).
    k : int
        Basis shapes of each half's rank-3K factor; lowered to the largest K both halves accept.
    visible : (F, P) array_like of bool, optional
    seed, n_starts : int
        As :func:`lipgen.nrsfm.reconstruct` (the starts of each half's corrective triple).
    start : (2F, P) array_like, optional
        With points missing: the whole sequence's completed tracks (e.g. ``dai``'s first stage at K,
        scaled as above). Each half's completion then starts from their subspace instead of from its
        own tracks interpolated in time: nearer its answer, so it usually takes fewer steps (body 1100,
        40 frames, a tenth hidden at random: 32 instead of 60, the same angle), while the answer is
        still the half's own (only its observed points decide it). Ignored for complete tracks.

    Returns
    -------
    angle : float
        Median over the odd frames 2i + 1 of :func:`rotation_disagreement` between the odd half's
        rotation and the even half's halfway between frames 2i and 2i + 2; NaN when not tested.
    record : dict
        ``angle_deg`` (the median), ``mean_deg``, ``k`` (of the halves, None if not tested),
        ``reason``.
    """
    from lipgen.nrsfm.engine import _dai_rotations, _normalise_scale

    tracks = check_tracks(_normalise_scale(W, visible)[0], visible)
    F, P = tracks.mask.shape
    if F // 2 < MIN_HALF_FRAMES:
        return float("nan"), {"angle_deg": float("nan"), "mean_deg": float("nan"), "k": None,
                              "reason": f"{F} frames: halves shorter than {MIN_HALF_FRAMES} frames, "
                                        "not tested"}
    kk = _half_k(k, F, P, tracks.mask)
    if kk < 1:
        return float("nan"), {"angle_deg": float("nan"), "mean_deg": float("nan"), "k": None,
                              "reason": "no K fits the halves: not tested"}
    if start is not None and not tracks.complete:   # a bad start is the caller's error, not a half's
        from lipgen.nrsfm.completion import _start_rows

        _start_rows(start, P, 3 * kk)
    halves = []
    for first in (0, 1):
        rows = np.arange(2 * F).reshape(F, 2)[first::2].ravel()
        vis = None if tracks.complete else tracks.mask[first::2]
        try:
            half = check_tracks(tracks.W[rows], vis)
            halves.append(_dai_rotations(half, kk, seed=seed, n_starts=n_starts, start=start)[3])
        except ValueError as err:  # a degenerate half (rank < 3, a point never seen): no figure
            return float("nan"), {"angle_deg": float("nan"), "mean_deg": float("nan"), "k": kk,
                                  "reason": f"a half could not be solved ({err}): not tested"}
    between = _midpoints(halves[0])            # the even half at the odd frames' times
    n = min(len(between), len(halves[1]))
    angles = rotation_disagreement(between[:n], halves[1][:n])
    angle = float(np.median(angles))
    spread = 0.5 * (view_spread(halves[0]) + view_spread(halves[1]))
    log.info("even / odd frames' rotations disagree by %.3g deg (median; halves at K = %d; views spread "
             "%.3g deg)", angle, kk, spread)
    return angle, {"angle_deg": angle, "mean_deg": float(np.mean(angles)), "spread_deg": spread, "k": kk,
                   "reason": "even / odd frames"}


@single_threaded(always=True)
def rival_minimum(M: np.ndarray, R: np.ndarray, cost: float, *, n_starts: int = RIVAL_STARTS, seed: int = 0,
                  ratio: float = RIVAL_COST, angle: float = RIVAL_DEG) -> dict:
    """Search for another corrective triple that fits as well as the chosen one with other rotations.

    The corrective triple's cost (:func:`lipgen.nrsfm._rotation.corrective_triple`) often has several
    minima; the search keeps the best of a few starts, the first of them the rigid guess. When a
    triple from a seeded random start reaches at most ``ratio`` times the chosen cost with rotations
    that differ by more than ``angle`` degrees (median, :func:`rotation_disagreement`), the tracks do
    not prefer the chosen rotations. Each start runs to its minimum (up to 300 Levenberg-Marquardt
    steps, :func:`lipgen.nrsfm._lm.levenberg_marquardt`); the search stops at the first rival.

    Parameters
    ----------
    M : (2F, r) float
        The rank-3K motion factor the chosen triple was found on.
    R : (F, 3, 3) float
        The chosen triple's rotations (before their per-frame signs are resolved, or after).
    cost : float
        The chosen triple's cost.
    n_starts, seed : int
        Random starts (drawn from ``numpy.random.default_rng(seed + 123)``).
    ratio, angle : float

    Returns
    -------
    dict
        ``found`` (bool), ``starts`` (tried), and for a rival ``cost_ratio`` and ``angle_deg``.
    """
    from lipgen.nrsfm._lm import levenberg_marquardt
    from lipgen.nrsfm._rotation import _Metric, rotations_from_triple

    M = np.asarray(M, dtype=np.float64)
    if M.ndim != 2 or M.shape[0] != 2 * len(R) or M.shape[1] < 3:
        raise ValueError(f"M must be (2F, r >= 3) for the F = {len(R)} rotations given, got shape {M.shape}")
    metric = _Metric(M[0::2], M[1::2])
    r = M.shape[1]
    limit = ratio * float(cost)
    rng = np.random.default_rng(int(seed) + 123)
    for i in range(int(n_starts)):
        g0 = rng.standard_normal((r, 3))
        x, c, _ = levenberg_marquardt(metric.residual, metric.jacobian, g0.ravel(), max_iter=300)
        if c <= limit:
            other, _ = rotations_from_triple(M, x.reshape(r, 3))
            apart = float(np.median(rotation_disagreement(other, R)))
            if apart > angle:
                return {"found": True, "starts": i + 1, "cost_ratio": c / cost if cost > 0 else float("inf"),
                        "angle_deg": apart}
    return {"found": False, "starts": int(n_starts)}


@single_threaded(always=True)
def depth_support(W, k: int, visible=None, *, threshold: float = SUPPORT_DEG, seed: int = 0,
                  n_starts: int = 4, first_stage=None) -> tuple[bool, dict]:
    """Whether the tracks determine ``dai``'s rotations at K (see the module docstring).

    Not supported when both (1) the even and the odd frames alone give rotations that disagree by more
    than ``threshold`` degrees (:func:`rotation_stability`) and (2) the whole sequence's motion factor
    has a rival corrective triple (:func:`rival_minimum`): a triple that fits about as well with other
    rotations.

    Parameters
    ----------
    W : (2F, P) array_like
    k : int
    visible : (F, P) array_like of bool, optional
    threshold : float
        Degrees (default :data:`SUPPORT_DEG`).
    seed, n_starts : int
        As :func:`lipgen.nrsfm.reconstruct`.
    first_stage : tuple, optional
        ``dai``'s first stage at K on these tracks (:func:`lipgen.nrsfm.engine._dai_rotations` of the
        scaled tracks), when it was already run; else it is run here when (2) is needed.

    Returns
    -------
    supported : bool
        True also when the test cannot be made (too few frames; ``record["tested"]`` False).
    record : dict
        :func:`rotation_stability`'s record with ``supported``, ``tested``, ``threshold_deg``, ``rival``
        (:func:`rival_minimum`'s record, None when (1) held) and ``reason``.
    """
    from lipgen.nrsfm._tracks import factor
    from lipgen.nrsfm.engine import _dai_rotations, _normalise_scale

    if isinstance(threshold, bool) or not isinstance(threshold, (int, float, np.integer, np.floating)) \
            or not 0.0 <= float(threshold) < 180.0:
        raise ValueError(f"threshold must be an angle in degrees in [0, 180), got {threshold!r}")
    # the halves' completions start from the whole sequence's (its first stage's centred tracks)
    angle, record = rotation_stability(W, k, visible, seed=seed, n_starts=n_starts,
                                       start=None if first_stage is None else first_stage[0])
    tested = bool(np.isfinite(angle))
    record = record | {"tested": tested, "threshold_deg": float(threshold), "rival": None}
    if not tested or angle <= threshold:
        if tested:
            record["reason"] = (f"the even and odd frames' rotations disagree by {angle:.3g} deg (median), "
                                f"within {threshold:g} deg")
        return True, record | {"supported": True}
    if first_stage is None:
        scaled = _normalise_scale(W, visible)[0]
        first_stage = _dai_rotations(check_tracks(scaled, visible), int(k), seed=seed, n_starts=n_starts)
    Wc, _, info, R = first_stage
    M = factor(Wc, min(3 * int(k), info["rank"]))[0]
    rival = rival_minimum(M, R, info["rotation_cost"], seed=seed)
    halves = f"the even and odd frames' rotations disagree by {angle:.3g} deg (median, above {threshold:g})"
    if rival["found"]:
        reason = (f"{halves}, and a corrective triple whose rotations are {rival['angle_deg']:.3g} deg away "
                  f"reaches {rival['cost_ratio']:.3g} times the chosen one's cost: the tracks do not "
                  "determine the rotations")
    else:
        reason = (f"{halves}, but no other corrective triple of {rival['starts']} random starts fits within "
                  f"{RIVAL_COST:g} times its cost")
    return not rival["found"], record | {"supported": not rival["found"], "rival": rival, "reason": reason}


def flat_answer(rec: Reconstruction, record: dict) -> Reconstruction:
    """``rec`` with zero depth in every frame: the flat answer, its rotations, translations and image kept.

    Parameters
    ----------
    rec : Reconstruction
    record : dict
        Kept as ``info["depth_support"]`` (why the depth was dropped).

    Returns
    -------
    Reconstruction
        Camera-frame shapes ``(x, y, 0)`` of ``rec`` (each frame at its mean depth), so its
        reprojection is ``rec``'s; ``info["depth_factor"]`` is 0.
    """
    from lipgen.nrsfm.consensus import with_depth

    z = np.zeros(rec.shapes[:, 2].shape)
    return with_depth(rec, z, {"depth_support": record, "depth_factor": 0.0})
