"""The held-out validation bodies, the truth-free plausibility guard, and dai-ba's refusal of a
refinement that improves no truth-free criterion (lower cost without inflated depth)."""

import functools

import numpy as np
import pytest

import lipgen.nrsfm.engine as engine
from lipgen.experiments.nrsfm_benchmarks import flat_e3d
from lipgen.nrsfm import e3d, reconstruct
from lipgen.nrsfm.keep import DEPTH_KEEP, ROUGHNESS_KEEP, keep_refinement
from lipgen.nrsfm.plausibility import depth_ratio, plausible, roughness, shape_figures
from lipgen.nrsfm.validation import MOTIONS, human_sequence, validation_set


@functools.cache
def _dai_on_body(seed: int, k: int):
    """``reconstruct(human_sequence(seed, 40).W, k, method="dai")``, computed once for the tests that
    compare dai-ba's answer with it (the same bytes whatever ran before: test_nrsfm_determinism);
    its arrays are made read-only, so that no test changes them for the next."""
    rec = reconstruct(human_sequence(seed, 40).W, k, method="dai")
    for a in (rec.rotations, rec.weights, rec.basis, rec.translation):
        a.flags.writeable = False
    return rec


def test_validation_bodies_are_seeded_human_sized_and_orthographic():
    seqs = validation_set(seeds=range(100, 104), n_frames=40)
    assert [s.motion for s in seqs] == list(MOTIONS)
    for s in seqs:
        F, P = s.W.shape[0] // 2, s.W.shape[1]
        assert F == 40 and 40 <= P <= 75 and s.S.shape == (3 * F, P)
        shapes = s.S.reshape(F, 3, P)
        assert np.allclose(shapes.mean(axis=2), 0, atol=1e-9)           # centred camera frame
        W = s.W.reshape(F, 2, P)
        assert np.allclose(W - W.mean(2, keepdims=True), shapes[:, :2])   # orthographic projection
        assert np.allclose(s.R @ s.R.transpose(0, 2, 1), np.eye(3), atol=1e-12)
        # a body: taller than wide, with real depth
        spread = shapes.std(axis=2).mean(0)
        assert spread[1] > spread[0] and spread[2] > 0.1 * spread[1]
    again = human_sequence(101, 40)
    assert np.array_equal(again.W, seqs[1].W)
    with pytest.raises(ValueError, match="motion must be one of"):
        human_sequence(0, 40, motion="swim")


def test_dai_beats_the_flat_baseline_on_a_held_out_body():
    s = human_sequence(104, 80)  # (human-dance-102 at 80 frames, 126 degrees of turn, is not: 0.65 vs 0.47)
    rec = reconstruct(s.W, 3)
    assert rec.info["shapes"] == "trace norm"
    assert e3d(S_est=rec.S, S_true=s.S) < 0.9 * flat_e3d(s.W, s.S)  # 0.38 against 0.48


def test_plausibility_figures():
    rng = np.random.default_rng(0)
    t = np.linspace(0, 1, 50)[:, None, None]
    base = rng.standard_normal((1, 3, 20))
    smooth = base * (1 + 0.2 * np.sin(2 * np.pi * t))
    assert roughness(smooth) < 1e-2
    shaken = smooth.copy()
    shaken[:, 2] *= np.where(np.arange(50) % 2, 1.0, -1.0)[:, None]     # depth flipping every frame
    assert roughness(shaken, slice(2, 3)) > 100 * roughness(smooth, slice(2, 3))
    stretched = smooth * np.array([1.0, 1.0, 5.0])[None, :, None]
    assert depth_ratio(stretched) == pytest.approx(5 * depth_ratio(smooth))
    eye = np.broadcast_to(np.eye(3), (50, 3, 3))
    ref = shape_figures(eye, smooth)
    assert plausible(ref, ref)
    assert not plausible(shape_figures(eye, stretched), ref)
    assert not plausible(shape_figures(eye, shaken), ref)


def test_dai_ba_returns_its_start_when_the_refinement_shakes_depth(monkeypatch):
    s = human_sequence(102, 40)
    start = reconstruct(s.W, 2, method="dai")
    real = engine.bundle_adjust

    def shaking(W, R, C, B, t, mask, max_iter):
        # the same images with every other frame's depth mirrored: (R, C) -> (diag(-1, -1, 1) R, -C)
        R, C, B, t, history = real(W, R, C, B, t, mask, max_iter=2)
        R, C = R.copy(), C.copy()
        R[::2] = np.diag([-1.0, -1.0, 1.0]) @ R[::2]
        C[::2] = -C[::2]
        return R, C, B, t, history

    monkeypatch.setattr(engine, "bundle_adjust", shaking)
    rec = reconstruct(s.W, 2, method="dai-ba")
    assert rec.info["ba_kept"] is False
    assert np.array_equal(rec.S, start.S)


@pytest.mark.parametrize("seed,k,hidden", [(100, 2, 0.0), (101, 3, 0.0), (103, 2, 0.1)])
def test_dai_ba_keeps_only_a_lower_cost_uninflated_plausible_refinement_else_returns_dai(seed, k, hidden):
    """The refinement's contract, whatever the body: either it is kept, and then its reprojection error
    is below its start's, its depth ratio and depth roughness within DEPTH_KEEP and ROUGHNESS_KEEP of
    dai's and its figures within the plausibility limits of Dai's trace-norm shapes; or it is dropped,
    and the answer is `dai`'s, bit for bit."""
    s = human_sequence(seed, 40)
    F, P = s.W.shape[0] // 2, s.W.shape[1]
    visible = None if hidden == 0 else np.random.default_rng(seed).random((F, P)) > hidden
    W = s.W if visible is None else np.where(np.repeat(visible, 2, axis=0), s.W, np.nan)
    rec = reconstruct(W, k, method="dai-ba", visible=visible, refine_iter=20)
    dai = _dai_on_body(seed, k) if visible is None else reconstruct(W, k, method="dai", visible=visible)
    info = rec.info
    assert info["ba_cost"][1] <= info["ba_cost"][0]
    assert info["ba_start_shapes"] == pytest.approx(shape_figures(dai.rotations, dai.object_shapes), rel=1e-9)
    refined, start = info["ba_shapes"], info["ba_start_shapes"]
    improves = (info["ba_cost"][1] < info["ba_cost"][0]
                and refined["depth_ratio"] <= DEPTH_KEEP * start["depth_ratio"]
                and refined["depth_roughness"] <= ROUGHNESS_KEEP * start["depth_roughness"]
                and plausible(refined, info["trace_norm_shapes"]))
    assert info["ba_kept"] == improves
    if info["ba_kept"]:
        kept = shape_figures(rec.rotations, np.einsum("fk,kip->fip", rec.weights, rec.basis))
        assert kept == pytest.approx(info["ba_shapes"], rel=1e-9)
        assert depth_ratio(rec.shapes) <= DEPTH_KEEP * depth_ratio(dai.shapes) * (1 + 1e-9)
        assert rec.reprojection_rms <= info["rank_k_reprojection_rms"] * (1 + 1e-9)
    else:
        assert np.array_equal(rec.S, dai.S) and np.array_equal(rec.rotations, dai.rotations)


def test_keep_rule_closed_cases():
    """keep_refinement on figures: each condition alone refuses; at the limits it keeps."""
    ref = {"depth_ratio": 0.4, "depth_roughness": 1e-4}
    good = {"depth_ratio": 0.4 * DEPTH_KEEP, "depth_roughness": 1e-4 * ROUGHNESS_KEEP}
    assert keep_refinement([2.0, 1.0], good, ref, ref)
    assert not keep_refinement([2.0, 2.0], good, ref, ref)              # no lower cost
    assert not keep_refinement([2.0], good, ref, ref)                   # no step made
    assert not keep_refinement([2.0, 1.0], good | {"depth_ratio": 0.4 * DEPTH_KEEP * 1.001}, ref, ref)
    rough = good | {"depth_roughness": 1e-4 * ROUGHNESS_KEEP * 1.001}
    assert not keep_refinement([2.0, 1.0], rough, ref, ref)
    # within the limits of dai's answer, but not plausible against the trace-norm shapes
    assert not keep_refinement([2.0, 1.0], good, ref, {"depth_ratio": 0.1, "depth_roughness": 1e-4})


def _scaled_depth(factor, cost_ratio):
    """A stand-in refinement: dai's own answer with its camera-frame depth times ``factor`` and a cost
    history that falls to ``cost_ratio`` of its start."""
    def refine(W, R, C, B, t, mask, max_iter):
        F = R.shape[0]
        shapes = np.einsum("fk,kip->fip", C, B)
        cam = R @ shapes
        cam[:, 2] *= factor
        obj = np.einsum("fji,fjp->fip", R, cam)
        U, sv, Vt = np.linalg.svd(obj.reshape(F, -1), full_matrices=False)
        r = int((sv > 1e-12 * sv[0]).sum())
        return R.copy(), U[:, :r] * sv[:r], Vt[:r].reshape(r, 3, -1), t.copy(), [1.0, cost_ratio]
    return refine


@pytest.mark.parametrize("factor,cost_ratio,kept", [(0.5, 0.5, True), (3.0, 0.5, False), (0.5, 1.0, False),
                                                    (1.2, 0.5, True), (1.6, 0.5, False)])
def test_dai_ba_keep_rule_on_constructed_refinements(monkeypatch, factor, cost_ratio, kept):
    """Constructed refinements of dai's answer, its depth scaled: with a lower cost, shallower or up to
    DEPTH_KEEP times deeper depth is kept (its arrays are returned; depth roughness scales with the
    square of the factor, within ROUGHNESS_KEEP at 1.2); 3 and 1.6 times deeper, or no lower cost,
    return dai's answer bit for bit."""
    s = human_sequence(101, 40)
    dai = _dai_on_body(101, 3)
    stand_in = _scaled_depth(factor, cost_ratio)

    unit = dai.info.get("scale", 1.0)   # the engine works on tracks divided by this power of two

    def from_dai_answer(W, R, C, B, t, mask, max_iter):   # refine dai's answer, not the K-shape fit
        return stand_in(W, dai.rotations, dai.weights, dai.basis / unit, dai.translation / unit, mask,
                        max_iter)

    monkeypatch.setattr(engine, "bundle_adjust", from_dai_answer)
    rec = reconstruct(s.W, 3, method="dai-ba")
    assert rec.info["ba_kept"] is kept
    if kept:
        def centred_depth(shapes):
            return shapes[:, 2] - shapes[:, 2].mean(axis=1, keepdims=True)

        tol = 1e-9 * np.abs(dai.shapes).max()
        assert np.allclose(rec.shapes[:, :2], dai.shapes[:, :2], atol=tol)
        assert np.allclose(centred_depth(rec.shapes), factor * centred_depth(dai.shapes), atol=tol)
    else:
        assert np.array_equal(rec.S, dai.S) and np.array_equal(rec.rotations, dai.rotations)


def test_dai_ba_returns_its_start_when_nothing_improves(monkeypatch):
    """A refinement that changes nothing improves no criterion: the answer is dai's, bit for bit."""
    s = human_sequence(101, 40)
    start = _dai_on_body(101, 3)

    def idle(W, R, C, B, t, mask, max_iter):
        return R.copy(), C.copy(), B.copy(), t.copy(), [1.0]

    monkeypatch.setattr(engine, "bundle_adjust", idle)
    rec = reconstruct(s.W, 3, method="dai-ba")
    assert rec.info["ba_kept"] is False
    assert np.array_equal(rec.S, start.S) and np.array_equal(rec.weights, start.weights)
    assert np.array_equal(rec.rotations, start.rotations) and np.array_equal(rec.basis, start.basis)


def test_experiment_reports_validation_beside_the_flat_baseline(tmp_path):
    from lipgen.experiments.nrsfm_benchmarks import NrsfmBenchSettings, run_nrsfm_benchmarks

    # short bodies: dai's automatic K runs dai at every candidate K (up to 15 at 40 frames: 35 s of
    # CPU), and the report's layout does not depend on the length
    settings = NrsfmBenchSettings(methods=("dai",), sequences=(), validation_seeds=(104,),
                                  validation_ks=(2,), validation_frames=16, check_seeds=(300,),
                                  check_frames=(12,), mocap_clips=())
    result = run_nrsfm_benchmarks(tmp_path, settings)
    (entry,) = result["validation"]
    assert [r["auto"] for r in entry["runs"]] == [False, True]
    assert all(r["cpu_seconds"] > 0 and np.isfinite(r["e3d"]) for r in entry["runs"])
    text = (tmp_path / "benchmarks.md").read_text()
    assert "human-walk-104" in text and f"{entry['flat_e3d']:.3f}" in text
    assert "worse than the flat baseline" in text
    (check,) = result["check"]
    assert check["name"] in text and np.isfinite(check["e3d"]) and check["k"] >= 1
    assert 0.0 <= check["consensus_factor"] <= 1.0 and np.isfinite(check["e3d_single"])
    assert f"| {check['name']} | no |" in text          # seed 300 was looked at while choosing the rules
    # 12 frames: halves of 6 frames are too short for the depth-support test (lipgen.nrsfm.support)
    assert check["depth_supported"] and "halves (deg)" in text and "Depth dropped (flat answer): 0" in text


def test_a_flat_answer_is_not_worse_than_the_flat_baseline():
    # human-dance-1410's flat answer came out 1.5e-12 above the baseline (another path, rounding),
    # and the report counted it worse than flat
    from lipgen.experiments.nrsfm_report import worse_than_flat

    assert not worse_than_flat(0.586912044033518, 0.5869120440320119)
    assert worse_than_flat(0.5875, 0.5869120440320119)
    assert not worse_than_flat(0.36, 0.5869)
