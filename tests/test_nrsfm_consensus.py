"""The consensus depth of the smoothest Ks, shrunk by the James-Stein factor of their spread
(lipgen.nrsfm.consensus), the last step of k="auto" for dai."""

import numpy as np
import pytest

from lipgen.nrsfm import e3d
from lipgen.nrsfm._rotation import expm_so3
from lipgen.nrsfm.consensus import consensus_depth, consensus_reconstruction, design_effect, with_depth
from lipgen.nrsfm.engine import reconstruct_k
from lipgen.nrsfm.kchoice import candidate_ks, smooth_k
from lipgen.nrsfm.record import Reconstruction
from lipgen.nrsfm.synthetic import low_rank_sequence


def _rotations(F, rate, rng):
    """Smooth rotations turning by ``rate`` rad per frame about a random axis (roughness grows with rate)."""
    axis = rng.standard_normal(3)
    axis /= np.linalg.norm(axis)
    return expm_so3(np.arange(F)[:, None] * rate * axis)


def _record(cam, R, k, shapes="trace-norm"):
    """A Reconstruction whose camera-frame shapes are ``cam`` (F, 3, P) seen by rotations R."""
    F = cam.shape[0]
    return Reconstruction(rotations=R, weights=np.eye(F), basis=np.einsum("fji,fjp->fip", R, cam),
                          translation=np.zeros((F, 2)), method="dai", k=k, reprojection_rms=0.0,
                          info={"shapes": shapes})


def _centre(a):
    return a - a.mean(axis=-1, keepdims=True)


def test_identical_depths_are_kept_and_signs_aligned():
    rng = np.random.default_rng(0)
    F, P = 12, 9
    cam = _centre(rng.standard_normal((F, 3, P)))
    flipped = cam * np.array([1.0, 1.0, -1.0])[None, :, None]        # the same depth, globally reflected
    recs = [_record(c, _rotations(F, 0.01 * (i + 1), rng), i + 1) for i, c in enumerate((cam, flipped, cam))]
    z, record = consensus_depth(recs, 0, m=3)
    np.testing.assert_allclose(z, cam[:, 2], atol=1e-12)
    assert record["factor"] == 1.0 and record["ks"] == [1, 2, 3]


def _two_depths():
    """Two runs whose depths are z + d and z - d, d orthogonal to z with |d|^2 = |z|^2 / 4.

    Returns the generator (as it is left), the camera-frame shapes (F, 3, P), z and the runs."""
    rng = np.random.default_rng(1)
    F, P = 10, 8
    cam = _centre(rng.standard_normal((F, 3, P)))
    z = cam[:, 2]
    d = _centre(rng.standard_normal((F, P)))
    d -= z * np.sum(d * z) / np.sum(z * z)
    d *= 0.5 * np.sqrt(np.sum(z * z) / np.sum(d * d))                 # |d|^2 = |z|^2 / 4
    a, b = cam.copy(), cam.copy()
    a[:, 2], b[:, 2] = z + d, z - d
    recs = [_record(a, _rotations(F, 0.01, rng), 3), _record(b, _rotations(F, 0.02, rng), 4)]
    return rng, cam, z, recs


def test_james_stein_factor_closed_form():
    """Two depths z + d and z - d with d orthogonal to z: mean z, spread |d|^2 (sum over 1 degree of
    freedom, over m = 2), factor 1 - |d|^2 / |z|^2."""
    rng, cam, z, recs = _two_depths()
    F, P = z.shape
    out, record = consensus_depth(recs, 0, m=2)
    assert record["factor"] == pytest.approx(0.75, abs=1e-12)
    np.testing.assert_allclose(out, 0.75 * z, atol=1e-12)
    # three unrelated depths (orthogonal, equal norms): the spread explains all of the mean, factor 0
    q, _ = np.linalg.qr(rng.standard_normal((F * P, 3)))
    cams = []
    for i in range(3):
        c = cam.copy()
        c[:, 2] = q[:, i].reshape(F, P)
        c[:, 2] -= c[:, 2].mean(axis=1, keepdims=True)
        cams.append(c)
    g = np.stack([c[:, 2].ravel() for c in cams])
    g = np.linalg.qr(g.T)[0].T                                  # re-orthonormalise after centring
    for c, row in zip(cams, g, strict=True):
        c[:, 2] = row.reshape(F, P)
    recs = [_record(c, _rotations(F, 0.01 * (i + 1), rng), i + 1) for i, c in enumerate(cams)]
    out, record = consensus_depth(recs, 0, m=3)
    assert record["factor"] == pytest.approx(0.0, abs=1e-9) and np.abs(out).max() < 1e-9


def test_the_smoothest_are_averaged_with_the_chosen():
    rng = np.random.default_rng(2)
    F, P = 15, 7
    cams = [_centre(rng.standard_normal((F, 3, P))) for _ in range(4)]
    rates = [0.05, 0.2, 0.01, 0.02]          # roughness order: 2, 3, 0, 1
    recs = [_record(c, _rotations(F, r, rng), k + 1)
            for k, (c, r) in enumerate(zip(cams, rates, strict=True))]
    _, record = consensus_depth(recs, 1, m=3)
    assert record["ks"] == [2, 3, 4]        # the chosen K first, then the two smoothest others


def test_shrinking_noisy_depths_lowers_the_error():
    """Depths = truth + independent noise as large as the truth: the shrunk mean of four is closer to the
    truth than any one of them, and than the flat answer (the James-Stein property)."""
    rng = np.random.default_rng(3)
    F, P = 40, 30
    truth = _centre(rng.standard_normal((F, 3, P)))
    recs = []
    for i in range(4):
        cam = truth.copy()
        cam[:, 2] += _centre(rng.standard_normal((F, P)))
        recs.append(_record(cam, _rotations(F, 0.01 * (i + 1), rng), i + 1))
    z, record = consensus_depth(recs, 0, m=4)
    err = np.sum((z - truth[:, 2]) ** 2)
    assert 0.3 < record["factor"] < 0.95
    assert err < min(np.sum((r.shapes[:, 2] - truth[:, 2]) ** 2) for r in recs)
    assert err < np.sum(truth[:, 2] ** 2)


def test_with_depth_changes_the_depth_alone():
    rng = np.random.default_rng(4)
    F, P = 9, 6
    cam = _centre(rng.standard_normal((F, 3, P)))
    rec = _record(cam, _rotations(F, 0.1, rng), 2)
    z = _centre(rng.standard_normal((F, P)))
    out = with_depth(rec, z, {"note": 1})
    np.testing.assert_allclose(out.shapes[:, :2], cam[:, :2], atol=1e-12)
    np.testing.assert_allclose(out.shapes[:, 2], z, atol=1e-12)
    assert np.array_equal(out.rotations, rec.rotations) and out.info["note"] == 1
    with pytest.raises(ValueError, match=r"z must be \(F, P\) = \(9, 6\), got shape \(6, 9\)"):
        with_depth(rec, z.T)


def test_bad_arguments():
    rng = np.random.default_rng(5)
    rec = _record(_centre(rng.standard_normal((5, 3, 4))), _rotations(5, 0.1, rng), 1)
    other = _record(_centre(rng.standard_normal((6, 3, 4))), _rotations(6, 0.1, rng), 2)
    with pytest.raises(ValueError, match="at least one"):
        consensus_depth([], 0)
    with pytest.raises(ValueError, match="chosen must index the 1 candidates, got 3"):
        consensus_depth([rec], 3)
    with pytest.raises(ValueError, match="m must be a positive integer, got 0"):
        consensus_depth([rec], 0, m=0)
    with pytest.raises(ValueError, match="shapes differ"):
        consensus_depth([rec, other], 0)


def test_an_exact_fit_is_kept_bit_for_bit():
    W, S, _ = low_rank_sequence(40, 15, 2, np.random.default_rng(4))
    runs = [reconstruct_k(W, k, "dai") for k in (1, 2, 3)]
    assert runs[1].info["shapes"] == "rank-K fit"
    out = consensus_reconstruction(runs, 1)
    assert out.info["depth_consensus"]["factor"] == 1.0
    assert out.info["depth_consensus"]["roughness_ratio"] is None   # the same keys as a consensus
    assert np.array_equal(out.S, runs[1].S) and np.array_equal(out.weights, runs[1].weights)


def test_auto_is_the_consensus_of_dai_at_every_k():
    """reconstruct_auto for dai: the chosen K's rotations with the consensus depth of dai's runs at
    every K (here both are needed: fewer Ks than the consensus averages); m = 1 gives the chosen K's
    reconstruction itself."""
    from threadpoolctl import threadpool_limits

    from lipgen.nrsfm import kchoice
    from lipgen.nrsfm.validation import human_sequence

    s = human_sequence(302, 20)
    rec = kchoice.reconstruct_auto(s.W, "dai", kmax=2, support=None)   # the test after it: test_nrsfm_support
    ks = candidate_ks(20, s.W.shape[1], s.W.size // 2, "dai", 2)
    runs = [reconstruct_k(s.W, k, "dai") for k in ks]
    assert rec.info["k_choice"]["finished"] == [True] * len(ks)
    chosen, _ = smooth_k(runs)
    i = ks.index(chosen)
    with threadpool_limits(1):          # as reconstruct_auto runs it
        expect = consensus_reconstruction(runs, i)
    assert rec.k == chosen and np.array_equal(rec.S, expect.S)
    assert np.array_equal(rec.rotations, runs[i].rotations)
    record = rec.info["depth_consensus"]
    assert record["ks"][0] == chosen and len(record["ks"]) == len(ks)
    np.testing.assert_allclose(rec.shapes[:, :2], runs[i].shapes[:, :2], atol=1e-9 * np.abs(s.W).max())
    assert np.array_equal(consensus_reconstruction(runs, i, 1).S, runs[i].S)
    assert np.isfinite(e3d(S_est=rec.S, S_true=s.S))


def test_design_effect_closed_form_and_monte_carlo():
    """(1 + (m - 1) rho) / (1 - rho): 1 for independent errors or one estimate, 2 for four at rho 0.2; and
    what it claims: the mean's error variance over the expected s2 / m, checked on correlated draws."""
    assert design_effect(4, 0.0) == 1.0 and design_effect(2, 0.5) == pytest.approx(3.0, abs=1e-12)
    assert design_effect(4, 0.2) == pytest.approx(2.0, abs=1e-12)
    m, rho = 4, 0.3
    cov = (1 - rho) * np.eye(m) + rho * np.ones((m, m))
    e = np.random.default_rng(7).standard_normal((40000, m)) @ np.linalg.cholesky(cov).T
    ratio = np.var(e.mean(axis=1)) / (np.mean(np.var(e, axis=1, ddof=1)) / m)
    assert ratio == pytest.approx(design_effect(m, rho), rel=0.03)


def test_correlated_errors_shrink_more_by_the_design_effect():
    """The closed form of test_james_stein_factor_closed_form with rho: m = 2, spread 1/4, so the factor
    is 1 - (1 + rho) / (1 - rho) / 4; rho 0 gives the same bytes as the default."""
    _, _, z, recs = _two_depths()
    out, record = consensus_depth(recs, 0, m=2, rho=0.2)
    assert record["design_effect"] == pytest.approx(1.5)
    assert record["factor"] == pytest.approx(0.625, abs=1e-12)
    np.testing.assert_allclose(out, 0.625 * z, atol=1e-12)
    assert np.array_equal(consensus_depth(recs, 0, m=2, rho=0.0)[0], consensus_depth(recs, 0, m=2)[0])
    for bad in (-0.1, 1.0, float("nan"), "0.2", True):
        with pytest.raises(ValueError, match="rho must be a correlation in"):
            consensus_depth(recs, 0, m=2, rho=bad)
    with pytest.raises(ValueError, match="m must be an integer of at least 2 .estimates averaged., got 1"):
        design_effect(1, 0.1)


def test_auto_with_rho_scales_only_the_depth(monkeypatch):
    """reconstruct_auto(rho=...) hands rho to the consensus; against rho 0 on the same runs it keeps the
    rotations and the image and scales the depth by the ratio of the two James-Stein factors."""
    from lipgen.nrsfm import kchoice
    from lipgen.nrsfm.validation import human_sequence

    default = []

    def spy(runs, chosen, m, rho, roughness_ratio=None):
        default.append(consensus_reconstruction(runs, chosen, m))
        return consensus_reconstruction(runs, chosen, m, rho, roughness_ratio)

    monkeypatch.setattr(kchoice, "consensus_reconstruction", spy)
    s = human_sequence(302, 12)
    out = kchoice.reconstruct_auto(s.W, "dai", kmax=2, support=None, rho=0.3)
    ref = default[0]
    a, b = ref.info["depth_consensus"], out.info["depth_consensus"]
    assert out.k == ref.k and np.array_equal(out.rotations, ref.rotations) and b["factor"] < a["factor"]
    assert b["design_effect"] == pytest.approx(design_effect(len(b["ks"]), 0.3)) and a["design_effect"] == 1.0
    scale = np.abs(s.W).max()
    np.testing.assert_allclose(out.shapes[:, :2], ref.shapes[:, :2], atol=1e-9 * scale)
    ratio = b["factor"] / a["factor"]
    np.testing.assert_allclose(out.shapes[:, 2], ref.shapes[:, 2] * ratio, atol=1e-9 * scale)


def test_auto_refuses_a_bad_rho_on_every_path_before_any_work():
    """A bad rho is refused even where it would not be used (another method, an exact fit)."""
    from lipgen.nrsfm import kchoice
    from lipgen.nrsfm.validation import human_sequence

    W = human_sequence(302, 12).W
    for method in ("dai", "bregler"):
        with pytest.raises(ValueError, match="rho must be a correlation in"):
            kchoice.reconstruct_auto(W, method, kmax=2, rho=1.5)


def test_a_roughness_ratio_leaves_out_rotations_much_rougher_than_the_smoothest():
    """Three runs turning at 0.01, 0.02 and 0.1 rad per frame (roughness about 2 a^4: 1, 16 and 10^4 times
    the least): ratio 20 averages the first two, ratio 1 the chosen one alone (unshrunk), None all three;
    the chosen run always stays, even when it is not the smoothest."""
    rng = np.random.default_rng(2)
    F, P = 12, 9
    cams = [_centre(rng.standard_normal((F, 3, P))) for _ in range(3)]
    rates = (0.01, 0.02, 0.1)
    recs = [_record(cams[i], _rotations(F, rates[i], rng), i + 1) for i in range(3)]
    assert consensus_depth(recs, 0, m=3)[1]["ks"] == [1, 2, 3]
    _, record = consensus_depth(recs, 0, m=3, roughness_ratio=20.0)
    assert record["ks"] == [1, 2] and record["roughness_ratio"] == 20.0
    z, record = consensus_depth(recs, 0, m=3, roughness_ratio=1)
    assert record["ks"] == [1] and record["factor"] == 1.0
    np.testing.assert_allclose(z, cams[0][:, 2], atol=1e-12)   # the chosen depth, unshrunk
    assert consensus_depth(recs, 2, m=3, roughness_ratio=20.0)[1]["ks"] == [3, 1, 2]
    for bad in (0.5, float("nan"), "5", True, np.bool_(True), -1, -np.inf):
        with pytest.raises(ValueError, match="roughness_ratio must be None or a number >= 1"):
            consensus_depth(recs, 0, m=3, roughness_ratio=bad)
    for good, ks in ((np.float32(20), [1, 2]), (np.int64(1), [1]), (1, [1]), (np.inf, [1, 2, 3])):
        record = consensus_depth(recs, 0, m=3, roughness_ratio=good)[1]
        assert record["ks"] == ks and type(record["roughness_ratio"]) is float


def test_an_infinite_ratio_keeps_every_k_even_beside_a_still_camera():
    """A run whose rotations do not change has roughness 0, and inf * 0 is nan: inf must still mean no
    filter, not 'the chosen K alone'."""
    rng = np.random.default_rng(6)
    F, P = 12, 9
    recs = [_record(_centre(rng.standard_normal((F, 3, P))), _rotations(F, a, rng), i + 1)
            for i, a in enumerate((0.0, 0.01, 0.02))]
    assert consensus_depth(recs, 0, m=3, roughness_ratio=np.inf)[1]["ks"] == [1, 2, 3]
    assert consensus_depth(recs, 0, m=3, roughness_ratio=1e6)[1]["ks"] == [1]   # only the still one


def test_auto_hands_the_roughness_ratio_to_the_consensus():
    """reconstruct_auto(roughness_ratio=...) reaches the consensus record; None is today's answer, bit for
    bit; a bad ratio is refused before any work, on every path."""
    from lipgen.nrsfm import kchoice
    from lipgen.nrsfm.validation import human_sequence

    s = human_sequence(302, 20)
    base = kchoice.reconstruct_auto(s.W, "dai", kmax=3, support=None)
    same = kchoice.reconstruct_auto(s.W, "dai", kmax=3, support=None, roughness_ratio=None)
    assert np.array_equal(base.S, same.S) and base.info["depth_consensus"]["roughness_ratio"] is None
    assert len(base.info["depth_consensus"]["ks"]) > 1
    one = kchoice.reconstruct_auto(s.W, "dai", kmax=3, support=None, roughness_ratio=1.0)
    record = one.info["depth_consensus"]
    assert record["roughness_ratio"] == 1.0 and one.k == base.k
    assert record["ks"] == [one.k] and record["factor"] == 1.0   # the chosen K alone, its own depth
    assert np.array_equal(one.rotations, base.rotations)
    for method in ("dai", "bregler"):
        with pytest.raises(ValueError, match="roughness_ratio must be None or a number >= 1"):
            kchoice.reconstruct_auto(s.W[:6], method, roughness_ratio=0.0)
