"""``dai`` at many K for ``k="auto"``, finished only at the Ks the choice needs.

``dai`` at one K is two stages: the rotations of the corrective triple (Levenberg-Marquardt on the
rank-3K factor, cost growing with K) and the shapes of least trace norm (an ADMM whose cost does not
depend on K, about 0.5 s on drink). :func:`lipgen.nrsfm.kchoice.smooth_k` needs only the rotations'
roughness, but of the rotations after their per-frame signs are resolved against the shapes
(:func:`lipgen.nrsfm._rotation.orient_frames`). Flipping every frame leaves the roughness bit for bit
the same; flipping some frames of a smooth sequence adds jumps. So the roughness of the rotations
before orientation is a lower bound of the finished one (equal when the frames turn alike, as on
drink, jaws and every body checked), and :func:`scan_smooth` finishes only the Ks whose answer can
matter: in order of the bound until the least roughness is known; then, in order of K, those within
``tol`` of it up to the chosen one (the smallest exact K-shape fit, else the smallest K); then, unless
the chosen K is an exact fit (kept as it is), in order of the bound until the ``m`` smoothest (the
consensus depth) are known. If a finished K's roughness ever falls below its bound, every K is
finished (the exhaustive search). On drink 5 of 13 Ks are finished, on jaws 3 of 15, on 80-frame
bodies 4 of 15.

With points missing, the first stage needs the tracks completed at rank 3K, and that completion at
every K was most of the time (drink with 10 % hidden: 7-8x the complete tracks' CPU).
:func:`scan_estimated` orders the work by estimates instead: the roughness after a completion stopped
at 10 steps, made firmer (30 steps, then the full first stage) only for the Ks the choice and the
consensus use, and those Ks finished. A stopped completion goes on from where it stopped
(:class:`lipgen.nrsfm.completion.SubspaceCompletion`), so a finished K is bit for bit ``dai``'s. An
estimate is no bound: a K whose estimate is far rougher than its full roughness is never finished, and
the answer then differs from the exhaustive search's.
"""

from __future__ import annotations

import logging

from lipgen.nrsfm._tracks import check_tracks
from lipgen.nrsfm.completion import SubspaceCompletion
from lipgen.nrsfm.engine import _EXACT_COMPLETION, _dai_rotations, _normalise_scale, _reconstruct, _scale_back
from lipgen.nrsfm.plausibility import rotation_roughness
from lipgen.nrsfm.record import Reconstruction, check_method_k

__all__ = ["DaiScan", "scan_smooth", "scan_estimated", "ESTIMATE_STEPS", "ESTIMATE_EXACT"]

log = logging.getLogger(__name__)

ESTIMATE_STEPS = (10, 30)
"""The caps on the completion's steps of :meth:`DaiScan.estimate`'s successive estimates (the full
completion takes up to 100)."""

ESTIMATE_EXACT = 1e-3
"""Completion misfit below which an estimate's K is treated as one that may fit K shapes exactly (the
full completion's test is ``_EXACT_COMPLETION``, 1e-6; a completion stopped early fits less well)."""


class DaiScan:
    """``dai`` on one sequence, each K's two stages run once and kept.

    Parameters
    ----------
    W : (2F, P) array_like
    visible : (F, P) array_like of bool, optional
    **options
        As :func:`lipgen.nrsfm.reconstruct` (``seed``, ``n_starts``, ``shape_starts``, ...).
    """

    def __init__(self, W, visible=None, **options):
        self.W, self.unit = _normalise_scale(W, visible)
        self.visible = visible
        self.tracks = check_tracks(self.W, visible)
        self.options = options
        self._rotations: dict[int, tuple] = {}
        self._estimates: dict[int, tuple] = {}
        self._completions: dict[int, SubspaceCompletion] = {}
        self._finished: dict[int, Reconstruction] = {}

    def bound(self, k: int) -> float:
        """Rotation roughness at K before the per-frame signs are resolved (the first stage only)."""
        if k not in self._rotations:
            F, P = self.tracks.mask.shape
            check_method_k(k, "dai", F, P, self.tracks.n_observed)
            # an estimate's completion goes on from where it stopped (the same steps, bit for bit)
            self._rotations[k] = _dai_rotations(self.tracks, k, seed=self.options.get("seed", 0),
                                                n_starts=self.options.get("n_starts", 4),
                                                completion=self._completions.pop(k, None))
        return rotation_roughness(self._rotations[k][3])

    def estimate(self, k: int) -> tuple[float, bool]:
        """An estimate of the rotation roughness at K, and whether K may fit K shapes exactly (see
        :meth:`may_be_exact`; with the looser misfit :data:`ESTIMATE_EXACT` while the completion is
        capped). Incomplete tracks only. First from ``dai``'s first stage on tracks completed with at most
        ``ESTIMATE_STEPS[0]`` steps; each :meth:`refine` goes on to the next cap, then to the full first
        stage (the estimate is then :meth:`bound`)."""
        if k not in self._estimates:
            F, P = self.tracks.mask.shape
            check_method_k(k, "dai", F, P, self.tracks.n_observed)
            if k not in self._rotations:   # else the first stage is known: refine takes its bound
                self._completions[k] = SubspaceCompletion(self.tracks.W, self.tracks.mask, 3 * k)
            self._estimates[k] = (0.0, False, -1)
            self.refine(k)
        return self._estimates[k][:2]

    def refine(self, k: int) -> bool:
        """Make K's estimate firmer (the completion goes on from where it stopped: the same steps, bit
        for bit); False if it is already the bound."""
        level = self._estimates[k][2] + 1
        if k in self._rotations or level >= len(ESTIMATE_STEPS):
            if self._estimates[k][2] == len(ESTIMATE_STEPS):
                return False
            self._estimates[k] = (self.bound(k), self.may_be_exact(k), len(ESTIMATE_STEPS))
            return True
        stage = _dai_rotations(self.tracks, k, seed=self.options.get("seed", 0),
                               n_starts=self.options.get("n_starts", 4),
                               completion_steps=ESTIMATE_STEPS[level], completion=self._completions[k])
        _, _, info, R = stage
        if self._completions[k].done:    # converged within the cap: the first stage itself
            self._rotations[k] = stage
            del self._completions[k]
        exact = info["rank"] <= 3 * k or info["completion_misfit"] <= ESTIMATE_EXACT
        self._estimates[k] = (rotation_roughness(R), bool(exact), level)
        return True

    def first_stage(self, k: int) -> tuple:
        """``dai``'s first stage at K (:func:`lipgen.nrsfm.engine._dai_rotations`), run once: the centred
        tracks (2F, P), translations (F, 2), the record and the rotations (F, 3, 3)."""
        self.bound(k)
        return self._rotations[k]

    def may_be_exact(self, k: int) -> bool:
        """Whether ``dai`` at K may fit exactly K shapes (:func:`lipgen.nrsfm.engine._dai_parts`
        tries only then: tracks of numerical rank <= 3K, or incomplete ones whose rank-3K completion
        fits the observed points to within ``_EXACT_COMPLETION``)."""
        self.bound(k)
        info = self._rotations[k][2]
        return bool(info["rank"] <= 3 * k or (not self.tracks.complete
                                              and info["completion_misfit"] <= _EXACT_COMPLETION))

    def finish(self, k: int) -> Reconstruction:
        """``dai``'s reconstruction at K, bit for bit ``reconstruct(W, k, "dai", visible, **options)``."""
        if k not in self._finished:
            self.bound(k)
            rec = _reconstruct(self.W, k, "dai", self.visible, **_engine_options(self.options),
                               tracks=self.tracks, rotations=self._rotations[k])
            self._finished[k] = _scale_back(rec, self.unit)
        return self._finished[k]


def _engine_options(options: dict) -> dict:
    defaults = {"seed": 0, "n_starts": 4, "shape_starts": 8, "refine_iter": 100, "em_iter": 500}
    return defaults | options


def scan_smooth(scan: DaiScan, ks: list[int], tol: float, m: int) -> tuple[list[Reconstruction], dict]:
    """Finish the Ks of ``ks`` that the smoothest-rotation choice and an ``m``-K consensus can need.

    Parameters
    ----------
    scan : DaiScan
    ks : list of int
        Candidate Ks.
    tol : float
        :func:`lipgen.nrsfm.kchoice.smooth_k`'s tolerance.
    m : int
        Number of the smoothest Ks the consensus averages.

    Returns
    -------
    runs : list of Reconstruction
        The finished Ks, in the order of ``ks``.
    bounds : dict
        K -> the lower bound of its roughness (every K of ``ks``).
    """
    bounds = {k: scan.bound(k) for k in ks}
    rough: dict[int, float] = {}

    def finish(k: int) -> bool:          # False: the bound failed
        if k not in rough:
            rough[k] = rotation_roughness(scan.finish(k).rotations)
        return rough[k] >= bounds[k]

    order = sorted(ks, key=lambda k: (bounds[k], k))

    def known(m_: int, strict: bool) -> bool:     # the m_ smoothest Ks are all finished
        top = sorted(rough.values())[:m_]
        nxt = next((bounds[k] for k in order if k not in rough), None)
        return len(top) >= m_ and (nxt is None or (top[-1] < nxt if strict else top[-1] <= nxt))

    def advance(m_: int, strict: bool) -> bool:   # finish in order of the bound until known
        for k in order:
            if known(m_, strict):
                break
            if k not in rough and not finish(k):
                return False
        return True

    # 1: the least roughness
    ok = advance(1, False)
    # 2: the K smooth_k chooses: the smallest exact K-shape fit within tol of the least roughness
    # (with every smaller K that might be one), else the smallest K within tol (likewise)
    limit = (1 + tol) * min(rough.values())
    near = [k for k in sorted(ks) if bounds[k] <= limit]
    chosen_exact = False
    for k in near:
        if ok and scan.may_be_exact(k):
            ok = finish(k)
            if ok and rough[k] <= limit and scan.finish(k).info.get("shapes") == "rank-K fit":
                chosen_exact = True
                break
    for k in near:
        if not ok or chosen_exact:
            break
        ok = finish(k)
        if rough[k] <= limit:
            break
    # 3: the m smoothest, whose depths the consensus averages (an exact fit is kept as it is)
    if ok and not chosen_exact:
        ok = advance(max(m, 1), True)
    if not ok:
        log.info("a finished K's rotation roughness fell below its bound; finishing every K")
        for k in ks:
            finish(k)
    return [scan.finish(k) for k in ks if k in rough], bounds


def scan_estimated(scan: DaiScan, ks: list[int], tol: float, m: int) -> tuple[list[Reconstruction], dict]:
    """Like :func:`scan_smooth` for incomplete tracks, guided by estimates instead of bounds.

    The full completion at every K is most of the cost of ``k="auto"`` with points missing, and the
    choice needs the roughness of few Ks. Every K gets an estimate (:meth:`DaiScan.estimate`); the
    choice of :func:`lipgen.nrsfm.kchoice.smooth_k` and the ``m``-K consensus are made on the finished
    Ks' roughness where known and the estimates elsewhere, every K they use is finished (with the full
    completion), and this repeats until they use finished Ks only. The answer is then ``dai``'s at
    those Ks, bit for bit; it differs from :func:`scan_smooth`'s only where an estimate hides a K
    that the full completion would have made smoother than the ones used.

    Parameters
    ----------
    scan : DaiScan
    ks : list of int
        Candidate Ks.
    tol : float
        :func:`lipgen.nrsfm.kchoice.smooth_k`'s tolerance.
    m : int
        Number of the smoothest Ks the consensus averages.

    Returns
    -------
    runs : list of Reconstruction
        The finished Ks, in the order of ``ks``.
    estimates : dict
        K -> the estimated roughness (every K of ``ks``).
    """
    estimates = {k: scan.estimate(k) for k in ks}
    rough: dict[int, float] = {}
    while True:
        todo = [k for k in _used(ks, estimates, rough, scan, tol, m) if k not in rough]
        if not todo:
            break
        k = todo[0]     # one at a time: a firmer estimate or a finished K may push the others out of use
        if scan.refine(k):
            estimates[k] = scan.estimate(k)
        else:
            rough[k] = rotation_roughness(scan.finish(k).rotations)
    log.info("k='auto' on incomplete tracks: %d of %d Ks finished", len(rough), len(ks))
    return [scan.finish(k) for k in ks if k in rough], {k: v[0] for k, v in estimates.items()}


def _used(ks, estimates, rough, scan, tol, m) -> list[int]:
    """The Ks that the choice and the consensus use, with the finished Ks' roughness and the others'
    estimates: the smoothest, every K within ``tol`` of it up to the chosen one, and (unless the chosen K
    is an exact K-shape fit) the ``m`` smoothest."""
    value = {k: rough.get(k, estimates[k][0]) for k in ks}
    order = sorted(ks, key=lambda k: (value[k], k))
    limit = (1 + tol) * value[order[0]]
    near = [k for k in sorted(ks) if value[k] <= limit]

    def exact(k: int) -> bool | None:     # None: not known before the K is finished
        if k in rough:
            return scan.finish(k).info.get("shapes") == "rank-K fit"
        return None if estimates[k][1] else False

    fits = [k for k in near if exact(k)]
    unknown = [k for k in near if exact(k) is None]
    if fits:   # the smallest exact fit is chosen and kept as it is; a smaller K may be one too
        used = [order[0]] + [k for k in unknown if k < fits[0]] + [fits[0]]
    else:      # the smallest K unless a K that may be an exact fit is one; the m smoothest for the consensus
        used = [order[0], near[0]] + unknown[:1] + order[: max(m, 1)]
    return list(dict.fromkeys(used))
