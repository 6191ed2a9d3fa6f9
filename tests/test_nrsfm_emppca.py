"""EM-PPCA (Torresani, Hertzmann & Bregler 2008): exact recovery of data drawn from its own model,
missing data, the K convention (modes beyond the mean shape), bad input."""

import numpy as np
import pytest

from lipgen.nrsfm import e3d, reconstruct, reprojection_curve
from lipgen.nrsfm.synthetic import low_rank_sequence, random_rotations


def _ppca_sequence(n_frames, n_points, k, rng):
    """Tracks drawn from the EM-PPCA model: mean shape + K Gaussian modes with z ~ N(0, I),
    uniform random rotations, a scale per frame (scaled orthography) and a translation per frame."""
    mean = rng.standard_normal((3, n_points))
    modes = 0.4 * rng.standard_normal((k, 3, n_points))
    z = rng.standard_normal((n_frames, k))
    R = random_rotations(n_frames, rng)
    scale = rng.uniform(0.6, 1.5, n_frames)
    shapes = scale[:, None, None] * (R @ (mean + np.einsum("fk,kip->fip", z, modes)))
    W = (shapes[:, :2] + 3.0 * rng.standard_normal((n_frames, 2))[:, :, None]).reshape(2 * n_frames, -1)
    return W, shapes.reshape(3 * n_frames, n_points)


def _check_rotations(R):
    F = R.shape[0]
    assert np.allclose(R @ R.transpose(0, 2, 1), np.broadcast_to(np.eye(3), (F, 3, 3)), atol=1e-10)
    assert np.allclose(np.linalg.det(R), 1.0, atol=1e-10)


@pytest.mark.parametrize("k", [0, 1, 3])
def test_recovers_its_own_model_exactly(k):
    rng = np.random.default_rng(20 + k)
    W, S = _ppca_sequence(80, 18, k, rng)
    rec = reconstruct(W, k, method="em-ppca")
    assert e3d(S_est=rec.S, S_true=S) < 1e-6
    _check_rotations(rec.rotations)
    assert rec.k == k and rec.weights.shape == (80, k + 1) and rec.basis.shape == (k + 1, 3, 18)
    assert np.allclose(rec.reproject(), W, atol=1e-6 * np.abs(W).max())
    assert rec.info["converged"]


def test_recovers_rank_k_shape_sequences_of_the_other_methods():
    # the other methods' generator: K basis shapes = em-ppca with K - 1 modes
    W, S, _ = low_rank_sequence(90, 20, 3, np.random.default_rng(5))
    assert e3d(S_est=reconstruct(W, 2, method="em-ppca").S, S_true=S) < 1e-6


def test_missing_data_recovery():
    rng = np.random.default_rng(31)
    W, S = _ppca_sequence(100, 20, 2, rng)
    visible = rng.random((100, 20)) > 0.2
    W_missing = np.where(np.repeat(visible, 2, axis=0), W, np.nan)
    rec = reconstruct(W_missing, 2, method="em-ppca", visible=visible)
    assert e3d(S_est=rec.S, S_true=S) < 1e-6
    assert np.allclose(rec.reproject(), W, atol=1e-6 * np.abs(W).max())  # hidden points predicted


def test_curve_counts_modes_and_finds_the_true_k():
    W, _ = _ppca_sequence(60, 16, 2, np.random.default_rng(9))
    curve = reprojection_curve(W, ks=[0, 1, 2, 3], method="em-ppca")
    assert curve.chosen == 2 and curve.method == "em-ppca"
    assert curve.relative[2] < 1e-6 < curve.relative[1]


def test_bad_inputs():
    W, _ = _ppca_sequence(20, 12, 1, np.random.default_rng(7))
    with pytest.raises(ValueError, match="odd number of rows"):
        reconstruct(W[:-1], 1, method="em-ppca")
    Wn = W.copy()
    Wn[3, 4] = np.nan
    with pytest.raises(ValueError, match="no visibility mask"):
        reconstruct(Wn, 1, method="em-ppca")
    # 12 points: 3(K + 1) <= 11, so at most 2 modes
    with pytest.raises(ValueError, match=r"k=3 is too large for method 'em-ppca'.*4 basis shapes.*k <= 2"):
        reconstruct(W, 3, method="em-ppca")
    with pytest.raises(ValueError, match="at least 0"):
        reconstruct(W, -1, method="em-ppca")
    with pytest.raises(TypeError, match="integer"):
        reconstruct(W, 1.5, method="em-ppca")
    with pytest.raises(ValueError, match="constant"):
        reconstruct(np.zeros_like(W), 0, method="em-ppca")
    line = np.outer(np.arange(40.0), np.ones(12)) * np.linspace(0, 1, 12)
    with pytest.raises(ValueError, match="rank 1 < 3"):
        reconstruct(line, 0, method="em-ppca")


def test_cli_em_ppca(tmp_path, capsys):
    from lipgen.cli import main
    from lipgen.nrsfm import load_shapes

    W, S = _ppca_sequence(40, 12, 1, np.random.default_rng(3))
    tracks = tmp_path / "tracks.npz"
    np.savez(tracks, W=W, S=S)
    out = tmp_path / "shapes.npz"
    assert main(["nrsfm", str(tracks), "--k", "auto", "--kmax", "2", "--method", "em-ppca",
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "chosen K = 1" in text and "\n0   " in text  # the curve starts at 0 modes
    saved = load_shapes(out)
    assert saved["weights"].shape == (40, 2) and saved["basis"].shape == (2, 3, 12)
    assert e3d(S_est=saved["S"], S_true=S) < 1e-6


def test_over_relaxation_keeps_the_answer_and_saves_iterations():
    from lipgen.nrsfm._tracks import check_tracks
    from lipgen.nrsfm.core import Reconstruction
    from lipgen.nrsfm.emppca import em_ppca

    W, S = _ppca_sequence(80, 18, 1, np.random.default_rng(21))
    tracks = check_tracks(W)
    iterations = {}
    for growth in (1.0, 1.2):  # 1.0: plain EM
        R, C, B, t, info = em_ppca(tracks, 1, relax_growth=growth)
        assert e3d(S_est=Reconstruction(R, C, B, t, "em-ppca", 1, 0.0).S, S_true=S) < 1e-6
        iterations[growth] = info["iterations"]
    assert iterations[1.2] < 0.6 * iterations[1.0]
