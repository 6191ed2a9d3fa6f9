"""Non-rigid structure from motion: exact recovery, missing data, the e3D metric, K choice, bad input, CLI."""


import numpy as np
import pytest

from lipgen.cli import main
from lipgen.experiments.nrsfm_benchmarks import data_dir
from lipgen.nrsfm import (
    MEAN_PLUS_MODES,
    METHODS,
    Reconstruction,
    choose_k,
    e3d,
    load_shapes,
    reconstruct,
    reprojection_curve,
)
from lipgen.nrsfm.synthetic import low_rank_sequence, random_rotations

BENCH = data_dir()


def _check_rotations(R):
    F = R.shape[0]
    assert np.allclose(R @ R.transpose(0, 2, 1), np.broadcast_to(np.eye(3), (F, 3, 3)), atol=1e-10)
    assert np.allclose(np.linalg.det(R), 1.0, atol=1e-10)
    assert np.allclose(R[:, 2], np.cross(R[:, 0], R[:, 1]), atol=1e-12)


# ---------------------------------------------------------------- e3D

def test_e3d_hand_computed():
    truth = np.array([[1.0, -1.0], [0.0, 0.0], [0.0, 0.0]])  # one frame, two points
    # s = mean of the row stds (1, 0, 0) = 1/3: points at +-3 after scaling; estimate at +-6
    assert e3d(S_est=2 * truth, S_true=truth) == pytest.approx(3.0)
    assert e3d(S_est=truth + 5.0, S_true=truth) == pytest.approx(0.0, abs=1e-15)  # rows are centred
    # two frames: the estimate's second frame collapsed to a point, 3 units from each true point
    truth2 = np.vstack([truth, truth])
    est = np.vstack([truth, np.zeros((3, 2))])
    assert e3d(S_est=est, S_true=truth2) == pytest.approx((0.0 + 3.0) / 2)


def test_e3d_invariances():
    rng = np.random.default_rng(0)
    S = rng.standard_normal((3 * 7, 9))
    assert e3d(S_est=S, S_true=S) == pytest.approx(0.0, abs=1e-14)
    for Q in (random_rotations(1, rng)[0], np.diag([1.0, 1.0, -1.0]) @ random_rotations(1, rng)[0]):
        turned = np.einsum("ij,fjp->fip", Q, S.reshape(7, 3, 9))
        assert e3d(S_est=turned, S_true=S) == pytest.approx(0.0, abs=1e-12)  # (F, 3, P) input accepted too
    noisy = S + 0.1 * rng.standard_normal(S.shape)
    assert e3d(S_est=4.0 * noisy, S_true=4.0 * S) == pytest.approx(e3d(S_est=noisy, S_true=S), rel=1e-12)
    with pytest.raises(ValueError, match="same shape"):
        e3d(S_est=S[:, :8], S_true=S)
    with pytest.raises(ValueError, match="undefined"):
        e3d(S_est=S, S_true=np.ones_like(S))


# ---------------------------------------------------------------- exact recovery

@pytest.mark.parametrize("method", sorted(METHODS))
def test_rigid_k1_exact_with_per_frame_scale(method):
    rng = np.random.default_rng(1)
    W, S, _ = low_rank_sequence(40, 15, 1, rng)
    scale = rng.uniform(0.5, 2.0, 40)  # scaled orthography: a zoom per frame
    W = W * np.repeat(scale, 2)[:, None]
    S = S * np.repeat(scale, 3)[:, None]
    k = 0 if method in MEAN_PLUS_MODES else 1  # one basis shape: em-ppca counts modes beyond the mean
    rec = reconstruct(W, k, method=method)
    assert e3d(S_est=rec.S, S_true=S) < 1e-7
    assert rec.reprojection_rms < 1e-7 * np.abs(W).max()
    _check_rotations(rec.rotations)


@pytest.mark.parametrize("k", [2, 3, 5])
def test_dai_recovers_low_rank_exactly(k):
    rng = np.random.default_rng(10 + k)
    W, S, _ = low_rank_sequence(120, 25, k, rng)
    rec = reconstruct(W, k, method="dai")
    assert e3d(S_est=rec.S, S_true=S) < 1e-6
    _check_rotations(rec.rotations)
    assert rec.weights.shape == (120, k) and rec.basis.shape == (k, 3, 25)
    assert np.allclose(rec.reproject(), W, atol=1e-5 * np.abs(W).max())


def _rank1_deformation_sequence(n_frames, n_points, n_rank1, rng):
    """A mean shape plus ``n_rank1`` rank-1 deformations (direction times per-point amount, as in
    Torresani's shark), turned by uniformly random rotations: tracks of rank 3 + n_rank1 < 3K."""
    k = 1 + n_rank1
    basis = np.zeros((k, 3, n_points))
    basis[0] = rng.standard_normal((3, n_points))
    for i in range(1, k):
        d = rng.standard_normal(3)
        basis[i] = np.outer(d / np.linalg.norm(d), rng.standard_normal(n_points))
    basis -= basis.mean(axis=2, keepdims=True)
    weights = np.ones((n_frames, k))
    weights[:, 1:] = 0.5 * rng.standard_normal((n_frames, k - 1))
    shapes = random_rotations(n_frames, rng) @ np.einsum("fk,kip->fip", weights, basis)
    W = (shapes[:, :2] + rng.standard_normal((n_frames, 2, 1))).reshape(2 * n_frames, n_points)
    return W, shapes.reshape(3 * n_frames, n_points), k


@pytest.mark.parametrize("seed", [0, 1])
def test_dai_exact_on_degenerate_rank_with_large_rotations(seed):
    # the least-trace-norm shapes are not of rank K here (the relaxation is not tight); the rank-K
    # fit with the rotations fixed must still land on the exact K-shape solution
    W, S, k = _rank1_deformation_sequence(120, 30, 2, np.random.default_rng(seed))
    assert np.linalg.matrix_rank(W - W.mean(1, keepdims=True), tol=1e-9 * np.abs(W).max()) == 5
    rec = reconstruct(W, k, method="dai")
    assert e3d(S_est=rec.S, S_true=S) < 1e-8
    assert rec.info["shape_exact"]
    _check_rotations(rec.rotations)


def test_dai_exact_on_degenerate_rank_with_missing_points():
    # the per-frame translations from the completed tracks are only a start; the fit moves them
    rng = np.random.default_rng(2)
    W, S, k = _rank1_deformation_sequence(120, 30, 2, rng)
    visible = rng.random((120, 30)) > 0.15
    rec = reconstruct(np.where(np.repeat(visible, 2, axis=0), W, np.nan), k, method="dai", visible=visible)
    assert e3d(S_est=rec.S, S_true=S) < 1e-6
    assert np.allclose(rec.reproject(), W, atol=1e-6 * np.abs(W).max())


def test_dai_exact_on_smoothly_turning_low_rank_sequence():
    W, S, _ = low_rank_sequence(150, 30, 3, np.random.default_rng(1), smooth=True)
    assert e3d(S_est=reconstruct(W, 3, method="dai").S, S_true=S) < 1e-6


def test_dai_ba_exact_and_bregler_is_not():
    rng = np.random.default_rng(3)
    W, S, _ = low_rank_sequence(100, 20, 3, rng)
    # dai's rank-K fit is exact to ~6e-9 here; the refinement lowers the cost (to ~1e-28) with the same
    # depth figures, so it is kept (e3D ~1e-15); either answer is exact
    assert e3d(S_est=reconstruct(W, 3, method="dai-ba").S, S_true=S) < 1e-8
    assert e3d(S_est=reconstruct(W, 3, method="bregler").S, S_true=S) > 0.05  # its 3x3 upgrade is not enough


def test_missing_data_recovery():
    rng = np.random.default_rng(4)
    W, S, _ = low_rank_sequence(100, 24, 3, rng)
    visible = rng.random((100, 24)) > 0.25
    W_missing = np.where(np.repeat(visible, 2, axis=0), W, np.nan)
    rec = reconstruct(W_missing, 3, method="dai-ba", visible=visible)
    assert e3d(S_est=rec.S, S_true=S) < 1e-6
    # the hidden points are predicted too
    assert np.allclose(rec.reproject(), W, atol=1e-6 * np.abs(W).max())
    assert e3d(S_est=reconstruct(W_missing, 3, method="dai", visible=visible).S, S_true=S) < 1e-3


def test_reconstruction_is_read_only():
    W, _, _ = low_rank_sequence(30, 10, 1, np.random.default_rng(5))
    rec = reconstruct(W, 1)
    assert isinstance(rec, Reconstruction)
    with pytest.raises(ValueError):
        rec.weights[0, 0] = 1.0
    assert rec.S.shape == (90, 10) and rec.shapes.shape == (30, 3, 10)


# ---------------------------------------------------------------- K from the curve

def test_choose_k_rule():
    assert choose_k([1, 2, 3, 4], [0.3, 0.1, 0.005, 0.001])[0] == 3
    # nothing under rtol: first K after which the curve flattens
    assert choose_k([1, 2, 3, 4], [0.3, 0.1, 0.098, 0.097], rtol=0.01)[0] == 2
    assert choose_k([1, 2, 3], [0.3, 0.2, 0.1], rtol=0.01)[0] == 3


def test_curve_finds_true_k():
    W, _, _ = low_rank_sequence(60, 16, 3, np.random.default_rng(6))
    curve = reprojection_curve(W, ks=[1, 2, 3, 4])
    assert curve.chosen == 3
    assert curve.relative[2] < 1e-6 < curve.relative[1]


# ---------------------------------------------------------------- bad input

def test_bad_inputs():
    W, _, _ = low_rank_sequence(20, 12, 2, np.random.default_rng(7))
    with pytest.raises(ValueError, match="odd number of rows"):
        reconstruct(W[:-1], 2)
    Wn = W.copy()
    Wn[3, 4] = np.nan
    with pytest.raises(ValueError, match="no visibility mask"):
        reconstruct(Wn, 2)
    with pytest.raises(ValueError, match=r"k=4 is too large.*k <= 3"):
        reconstruct(W, 4)
    with pytest.raises(ValueError, match="at least 1"):
        reconstruct(W, 0)
    with pytest.raises(ValueError, match="constant"):
        reconstruct(np.zeros_like(W), 1)
    line = np.outer(np.arange(40.0), np.ones(12)) * np.linspace(0, 1, 12)  # points on a line
    with pytest.raises(ValueError, match="rank 1 < 3"):
        reconstruct(line, 1)
    with pytest.raises(ValueError, match=r"visible must have shape \(F, P\) = \(20, 12\)"):
        reconstruct(W, 2, visible=np.ones((12, 20), bool))
    vis = np.ones((20, 12), bool)
    vis[0, 4] = False  # the NaN (frame 1, point 4) stays marked visible
    with pytest.raises(ValueError, match="marked visible"):
        reconstruct(Wn, 2, visible=vis)
    with pytest.raises(ValueError, match="unknown NRSfM method"):
        reconstruct(W, 2, method="magic")


# ---------------------------------------------------------------- CLI and the benchmark data

def test_cli_round_trip(tmp_path, capsys):
    W, S, _ = low_rank_sequence(50, 14, 2, np.random.default_rng(8))
    tracks = tmp_path / "tracks.npz"
    np.savez(tracks, W=W, S=S)
    out = tmp_path / "shapes.npz"
    assert main(["nrsfm", str(tracks), "--k", "2", "--out", str(out)]) == 0
    saved = load_shapes(out)
    assert saved["S"].shape == (150, 14) and saved["R"].shape == (50, 3, 3)
    assert saved["weights"].shape == (50, 2) and saved["basis"].shape == (2, 3, 14)
    assert e3d(S_est=saved["S"], S_true=S) < 1e-6
    assert "e3D" in capsys.readouterr().out
    assert main(["nrsfm", str(tracks), "--k", "2", "--out", str(out)]) == 1  # no silent overwrite
    assert "--force" in capsys.readouterr().err
    plot = tmp_path / "curve.png"
    assert main(["nrsfm", str(tracks), "--k", "auto", "--kmax", "3", "--out", str(out), "--force",
                 "--plot", str(plot)]) == 0
    printed = capsys.readouterr().out
    assert "chosen K = 2" in printed and plot.stat().st_size > 0
    row3 = next(line for line in printed.splitlines() if line.startswith("3 "))
    assert row3.endswith("(not finished: its bound)")   # K = 3: its bound, not a roughness
    assert main(["nrsfm", str(tracks), "--k", "two", "--out", str(out), "--force"]) == 1


@pytest.mark.skipif(not (BENCH / "jaws.npz").is_file(), reason="benchmark sequences not available")
def test_jaws_runs_and_bregler_is_far_worse_than_dai_on_drink_excerpt():
    with np.load(BENCH / "jaws.npz") as d:
        rec = reconstruct(d["W"], 2)
        assert e3d(S_est=rec.S, S_true=d["S"]) < 0.3
    with np.load(BENCH / "drink.npz") as d:
        W, S = d["W"][:400], d["S"][:600]  # first 200 frames
    err_dai = e3d(S_est=reconstruct(W, 6).S, S_true=S)
    err_bregler = e3d(S_est=reconstruct(W, 6, method="bregler").S, S_true=S)
    assert err_dai < 0.1 and err_bregler > 3 * err_dai


def test_evaluate_on_dataset(tmp_path):
    from lipgen.dataset.generate import generate
    from lipgen.dataset.layout import GenerateSettings
    from lipgen.nrsfm.dataset_eval import dataset_tracks, evaluate_on_dataset

    path = generate(tmp_path / "ds", GenerateSettings(frames=12, seed=5, size=(160, 120), calib_frames=0),
                    progress=False)
    for view in ("real", "virtual"):
        data = dataset_tracks(path, view)
        assert data["pixels_rms"] < 1e-6  # the camera-frame truth reprojects onto the stored uv
        seen = np.repeat(data["visible"], 2, axis=0)
        assert np.allclose(data["W"][seen], data["W_all"][seen], atol=1e-6)
        assert data["S"].shape == (3 * 12, 17) and 0 < data["relief"] < 0.2
    result = evaluate_on_dataset(path, "real", k=1, method="dai")
    assert np.isfinite(result["e3d"]) and np.isfinite(result["flat_e3d"])
    assert result["frames"] == 12 and result["points"] == 17
    assert "e3D" in result["markdown"]
    # K chosen by the method: the report says whether the depth was kept and why (12 frames: the
    # halves are too short for the test, which says so)
    auto = evaluate_on_dataset(path, "real", k="auto", method="dai")
    assert auto["depth_supported"] is True
    assert "Depth kept:" in auto["markdown"] and "not tested" in auto["markdown"]
    with pytest.raises(ValueError, match="view must be one of"):
        evaluate_on_dataset(path, "left")
    from types import SimpleNamespace

    from lipgen.nrsfm.dataset_eval import _depth_sentence

    flat = SimpleNamespace(depth_supported=False, info={"depth_support": {"reason": "halves disagree",
                                                                          "spread_deg": 3.04}})
    assert _depth_sentence(flat) == (" Depth not supported by the tracks: the flat answer (zero depth): "
                                     "halves disagree; the views turn by 3.0 deg (median from their mean "
                                     "direction).")
    assert _depth_sentence(SimpleNamespace(depth_supported=True, info={})) == ""

    # Measured tracks: the truth's pixels plus 0.5 px noise, one mark lost for a few frames.
    from lipgen._io import load_npz
    from lipgen.dataset.layout import FRAME_KIND, SCHEMA, Dataset
    from lipgen.errors import DatasetError

    ds = Dataset(path)
    uv = np.array([load_npz(path / f["truth"], FRAME_KIND, SCHEMA)["uv"][1] for f in ds.manifest["frames"]])
    noisy = uv + np.random.default_rng(0).normal(0.0, 0.5, uv.shape)
    seen = np.isfinite(uv).all(axis=-1)
    seen[3:7, 2] = False
    data = dataset_tracks(path, "real", uv=noisy, seen=seen)
    assert 0.5 < data["pixels_rms"] < 0.9  # 0.5 px per axis: ~0.71 px per point, against the truth
    assert np.isnan(data["W"][2 * 3:2 * 7, 2]).all() and not data["visible"][3:7, 2].any()
    measured = evaluate_on_dataset(path, "real", k=1, method="dai", uv=noisy, seen=seen)
    assert "tracked by" in measured["markdown"] and np.isfinite(measured["e3d"])
    # the flat baseline is the same noisy tracks with zero depth (the truth's pixels only where
    # the tracks have none), not the truth's exact projections
    F, P = data["visible"].shape
    flat = np.zeros((F, 3, P))
    flat[:, :2] = np.where(np.isfinite(data["W"]), data["W"], data["W_all"]).reshape(F, 2, P)
    assert measured["flat_e3d"] == pytest.approx(e3d(S_est=flat, S_true=data["S"]), rel=1e-12)
    assert measured["flat_e3d"] != pytest.approx(result["flat_e3d"], rel=1e-6)  # the truth's flat
    with pytest.raises(DatasetError, match="were the tracks made from this dataset"):
        dataset_tracks(path, "real", uv=noisy[:5], seen=seen[:5])


def test_flat_baseline_fills_only_the_missing_entries_and_asks_for_a_fill():
    from lipgen.nrsfm.metrics import flat_e3d

    rng = np.random.default_rng(4)
    S = rng.standard_normal((3 * 6, 5))
    W = S.reshape(6, 3, 5)[:, :2].reshape(12, 5).copy()
    full = flat_e3d(W, S)
    F = np.zeros((6, 3, 5))
    F[:, :2] = W.reshape(6, 2, 5)
    assert full == pytest.approx(e3d(S_est=F, S_true=S), rel=1e-12) and full > 0
    hidden = W.copy()
    hidden[2:4, 1] = np.nan
    assert flat_e3d(hidden, S, fill=W) == pytest.approx(full, rel=1e-12)   # filled with the same values
    with pytest.raises(ValueError, match="2 missing entries and no fill"):
        flat_e3d(hidden, S)
    with pytest.raises(ValueError, match=r"fill must have W's shape \(12, 5\)"):
        flat_e3d(hidden, S, fill=W[:4])
