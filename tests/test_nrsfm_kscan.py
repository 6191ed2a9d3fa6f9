"""k="auto" finishes ``dai`` only at the Ks its choice needs (lipgen.nrsfm.kscan), with the exhaustive
search's answer bit for bit; and the corrective triple's Levenberg-Marquardt gives up a start that
cannot beat the best one."""

import copy

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from lipgen.nrsfm import reconstruct
from lipgen.nrsfm._lm import levenberg_marquardt
from lipgen.nrsfm.consensus import consensus_reconstruction
from lipgen.nrsfm.kchoice import candidate_ks, reconstruct_auto, smooth_k
from lipgen.nrsfm.kscan import DaiScan
from lipgen.nrsfm.synthetic import low_rank_sequence
from lipgen.nrsfm.validation import human_sequence

# dai at one K is a pure function of the tracks: the exhaustive references of the tests below share
# their runs (the 1101 body's Ks 1-6 serve both tests on it) instead of running dai twice at each K.
_DAI_RUNS = {}


def _dai(W, k, visible):
    key = (W.shape, W.tobytes(), k, None if visible is None else visible.tobytes())
    if key not in _DAI_RUNS:
        _DAI_RUNS[key] = reconstruct(W, k, method="dai", visible=visible)
    return copy.deepcopy(_DAI_RUNS[key])  # a copy: smooth_k and the consensus see a fresh run


def _exhaustive(W, kmax, visible=None):
    """``k="auto"`` as it was before the scan: ``dai`` at every K, then smooth_k and the consensus (the
    scan is compared with ``support=None``: the depth-support test after it is in test_nrsfm_support)."""
    F, P = W.shape[0] // 2, W.shape[1]
    n_obs = F * P if visible is None else int(visible.sum())
    ks = candidate_ks(F, P, n_obs, "dai", kmax)
    runs = [_dai(W, k, visible) for k in ks]
    with threadpool_limits(1):
        chosen, _ = smooth_k(runs)
        return consensus_reconstruction(runs, ks.index(chosen), 4), len(ks)


def _same(a, b):
    return all(np.array_equal(getattr(a, n), getattr(b, n)) for n in ("rotations", "weights", "basis",
                                                                       "translation"))


def _small_noisy_tracks(visible_share=None):
    """Rank-3 tracks of 30 frames and 20 points with 0.01 of noise: the scan skips one K of 5 (in
    0.3 s, against 3 s for the human bodies below); ``visible_share``: a random visibility mask."""
    W, _, _ = low_rank_sequence(30, 20, 3, np.random.default_rng(4))
    W = W + 0.01 * np.random.default_rng(1).standard_normal(W.shape)
    if visible_share is None:
        return W, None
    visible = np.random.default_rng(2).random((30, 20)) < visible_share
    return np.where(np.repeat(visible, 2, axis=0), W, np.nan), visible


def test_auto_equals_the_exhaustive_search_on_small_tracks_and_skips_work():
    W, _ = _small_noisy_tracks()
    rec = reconstruct_auto(W, "dai", kmax=5, support=None)
    ref, n = _exhaustive(W, 5)
    assert _same(rec, ref) and rec.k == ref.k
    finished = rec.info["k_choice"]["finished"]
    assert len(finished) == n and 4 <= sum(finished) < n      # the consensus needs 4; some were skipped
    W, _, _ = low_rank_sequence(40, 15, 2, np.random.default_rng(4))  # exact tracks: a rank-K fit
    rec = reconstruct_auto(W, "dai", kmax=4, support=None)
    ref, _ = _exhaustive(W, 4)
    assert _same(rec, ref) and rec.k == 2 and rec.info["shapes"] == "rank-K fit"
    W, visible = _small_noisy_tracks(0.9)
    rec = reconstruct_auto(W, "dai", visible, kmax=4, support=None)
    ref, _ = _exhaustive(W, 4, visible)
    assert _same(rec, ref)


def test_a_failed_bound_finishes_every_k_on_small_tracks(monkeypatch):
    W, _ = _small_noisy_tracks()
    bound = DaiScan.bound                 # the rotations as usual, but a bound no roughness reaches
    monkeypatch.setattr(DaiScan, "bound", lambda self, k: (bound(self, k), 1e9)[1])
    rec = reconstruct_auto(W, "dai", kmax=5, support=None)
    assert all(rec.info["k_choice"]["finished"])
    assert _same(rec, _exhaustive(W, 5)[0])


def test_estimated_scan_uses_only_finished_ks_on_small_incomplete_tracks(monkeypatch):
    W, visible = _small_noisy_tracks(0.9)      # the exhaustive search's runs are shared with the test above
    rec = reconstruct_auto(W, "dai", visible, kmax=4, support=None)
    record = rec.info["k_choice"]
    assert record["unfinished"] == "estimate"
    finished = {k for k, f in zip(record["ks"], record["finished"], strict=True) if f}
    assert {rec.k, *rec.info["depth_consensus"]["ks"]} <= finished
    ref, _ = _exhaustive(W, 4, visible)
    assert _same(rec, ref) and rec.k == ref.k
    # estimates below every roughness: every K is finished, and the answer is the exhaustive search's
    monkeypatch.setattr(DaiScan, "estimate", lambda self, k: (0.0, False))
    monkeypatch.setattr(DaiScan, "refine", lambda self, k: False)
    rec = reconstruct_auto(W, "dai", visible, kmax=4, support=None)
    assert all(rec.info["k_choice"]["finished"]) and _same(rec, ref)
    # the exact bounds as estimates: the same answer
    monkeypatch.setattr(DaiScan, "estimate", lambda self, k: (self.bound(k), self.may_be_exact(k)))
    assert _same(reconstruct_auto(W, "dai", visible, kmax=4, support=None), ref)


@pytest.mark.slow(cover="tests/test_nrsfm_kscan.py::test_auto_equals_the_exhaustive_search_on_small_tracks_and_skips_work")
def test_auto_equals_the_exhaustive_search_and_skips_work():
    # a development body, short: Ks 1-6 tried, 1 and 3 skipped (Ks 7-8 added 3.4 s of dai stages to
    # the scan and 6 s to the reference, and only more Ks skipped the same way)
    s = human_sequence(1101, 30)
    rec = reconstruct_auto(s.W, "dai", kmax=6, support=None)
    ref, n = _exhaustive(s.W, 6)
    assert _same(rec, ref) and rec.k == ref.k
    finished = rec.info["k_choice"]["finished"]
    assert len(finished) == n and 4 <= sum(finished) < n      # the consensus needs 4; some were skipped


@pytest.mark.slow(cover="tests/test_nrsfm_kscan.py::test_auto_equals_the_exhaustive_search_on_small_tracks_and_skips_work")
def test_auto_equals_the_exhaustive_search_on_exact_and_incomplete_tracks():
    W, _, _ = low_rank_sequence(40, 15, 2, np.random.default_rng(4))
    rec = reconstruct_auto(W, "dai", kmax=4, support=None)
    ref, _ = _exhaustive(W, 4)
    assert _same(rec, ref) and rec.k == 2 and rec.info["shapes"] == "rank-K fit"
    s = human_sequence(1100, 24)
    visible = np.random.default_rng(1).random((24, s.W.shape[1])) > 0.1
    W = np.where(np.repeat(visible, 2, axis=0), s.W, np.nan)
    rec = reconstruct_auto(W, "dai", visible, kmax=5, support=None)
    ref, _ = _exhaustive(W, 5, visible)
    assert _same(rec, ref)


@pytest.mark.slow(cover="tests/test_nrsfm_kscan.py::test_a_failed_bound_finishes_every_k_on_small_tracks")
def test_a_failed_bound_finishes_every_k(monkeypatch):
    s = human_sequence(1101, 30)
    bound = DaiScan.bound                 # the rotations as usual, but a bound no roughness reaches
    monkeypatch.setattr(DaiScan, "bound", lambda self, k: (bound(self, k), 1e9)[1])
    rec = reconstruct_auto(s.W, "dai", kmax=6, support=None)
    assert all(rec.info["k_choice"]["finished"])
    assert _same(rec, _exhaustive(s.W, 6)[0])


def _two_minima(x):   # zero cost at x = 1; a worse local minimum near x = -1
    return np.array([x[0] ** 2 - 1.0, 0.3 * (x[0] - 1.0)])


def _two_minima_jac(x):
    return np.array([[2.0 * x[0]], [0.3]])


def test_levenberg_marquardt_gives_up_only_a_start_that_cannot_win():
    x, cost, n = levenberg_marquardt(_two_minima, _two_minima_jac, np.array([-3.0]), max_iter=300)
    assert x[0] < 0 and cost > 0.1
    xb, costb, nb = levenberg_marquardt(_two_minima, _two_minima_jac, np.array([-3.0]), max_iter=300,
                                        beat=0.0)
    assert nb < n and costb == pytest.approx(cost, rel=1e-3)
    # a start that reaches a cost below the one to beat runs as it would alone, bit for bit
    free = levenberg_marquardt(_two_minima, _two_minima_jac, np.array([3.0]), max_iter=300)
    held = levenberg_marquardt(_two_minima, _two_minima_jac, np.array([3.0]), max_iter=300, beat=0.1)
    assert free[0].tobytes() == held[0].tobytes() and free[2] == held[2] and free[1] < 1e-20


def test_the_estimated_scan_finishes_only_the_ks_the_choice_and_consensus_use():
    """_used on hand-made roughness values (K -> (estimate, may be an exact fit)), tolerance 0.05,
    a 2-K consensus: the Ks it names are the ones scan_estimated finishes; the others stay unfinished."""
    from types import SimpleNamespace

    from lipgen.nrsfm.kscan import _used

    ks = [1, 2, 3, 4, 5]
    est = {1: (1.0, False), 2: (0.5, False), 3: (0.52, False), 4: (2.0, False), 5: (0.51, False)}
    # the smoothest (2), the smallest within 5 % of it (2), and the 2 smoothest (2, 5): not 1, 3, 4
    assert _used(ks, est, {}, None, 0.05, 2) == [2, 5]
    # K 3 may fit exactly: it must be finished to know (it would be chosen over 2's neighbours)
    assert _used(ks, est | {3: (0.52, True)}, {}, None, 0.05, 2) == [2, 3, 5]
    # K 2 finished and an exact K-shape fit: it is chosen as it is, no consensus needed
    scan = SimpleNamespace(finish=lambda k: SimpleNamespace(info={"shapes": "rank-K fit"}))
    assert _used(ks, est, {2: 0.5}, scan, 0.05, 2) == [2]
    # a finished K smoother than the estimates moves the choice: 4 finished at 0.3 is alone within 5 %
    scan = SimpleNamespace(finish=lambda k: SimpleNamespace(info={"shapes": "trace-norm"}))
    assert _used(ks, est, {4: 0.3}, scan, 0.05, 2) == [4, 2]
