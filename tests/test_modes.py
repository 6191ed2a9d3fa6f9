"""Learned modes (snapshot PCA) and the LLSE, checked against direct linear algebra."""

import numpy as np
import pytest

from lipgen import ModelFileError, TopologyMismatchError
from lipgen._io import save_npz
from lipgen.mesh.lipmesh import LipMesh
from lipgen.modes.llse import LLSE, LowRankCovariance, SumCovariance, llse
from lipgen.modes.model import ModeModel


def _frames(F=40, n=30, rank=12, seed=0):
    """Frames of n nodes from a random rank-limited process plus a mean, (F, n, 3)."""
    rng = np.random.default_rng(seed)
    basis = rng.normal(size=(rank, 3 * n))
    scales = np.geomspace(5.0, 0.05, rank)
    X = rng.normal(size=(F, rank)) * scales @ basis + rng.normal(size=3 * n)
    return X.reshape(F, n, 3)


def _strip_mesh(n):
    """A flat triangle strip with n nodes (n even), for topology checks."""
    k = n // 2
    V = np.array([[i, j, 0.0] for i in range(k) for j in range(2)])
    faces = [[2 * i, 2 * i + 2, 2 * i + 1] for i in range(k - 1)] + \
            [[2 * i + 1, 2 * i + 2, 2 * i + 3] for i in range(k - 1)]
    return LipMesh(V, np.array(faces), anchors=[0, 1])


def _align(S, ref):
    return S * np.sign(np.sum(S * ref, axis=1))[:, None]


def test_snapshot_pca_equals_direct_covariance_eigendecomposition():
    U = _frames(F=25, n=40, rank=30)  # fewer frames than DOFs: the snapshot path
    X = U.reshape(len(U), -1)
    C = np.cov(X, rowvar=False)  # unbiased 1/(F-1), 120 x 120
    w, V = np.linalg.eigh(C)
    w, V = w[::-1], V[:, ::-1].T
    m = ModeModel(n_modes=10, method="snapshot").fit(U)
    assert np.allclose(m.mean_, X.mean(0))
    assert np.allclose(m.explained_variance_, w[:10], rtol=1e-10)
    assert np.allclose(m.components_, _align(V[:10], m.components_), atol=1e-9)
    assert np.allclose(m.components_ @ m.components_.T, np.eye(10), atol=1e-10)
    assert np.isclose(m.total_variance_, np.trace(C))
    assert np.allclose(m.explained_variance_ratio_, w[:10] / np.trace(C))
    # The whole non-zero spectrum: F - 1 = 24 modes, reassembling the sample covariance exactly.
    assert len(m.full_variance_) == 24
    assert np.allclose(m.covariance("full").matrix(), C, atol=1e-10 * np.abs(C).max())
    # The 3n x 3n route gives the same model.
    d = ModeModel(n_modes=10, method="covariance").fit(U)
    assert np.allclose(d.components_, m.components_, atol=1e-9)
    assert np.allclose(d.explained_variance_, m.explained_variance_)


def test_signs_are_deterministic_and_order_free():
    U = _frames(F=30, n=20, rank=8, seed=3)
    a = ModeModel(5).fit(U)
    b = ModeModel(5).fit(U[np.random.default_rng(1).permutation(len(U))])
    assert np.allclose(a.components_, b.components_, atol=1e-10)
    big = np.abs(a.components_).argmax(axis=1)
    assert (a.components_[np.arange(5), big] > 0).all()


def test_synthesize_project_roundtrip():
    m = ModeModel(6).fit(_frames())
    c = np.random.default_rng(2).normal(size=(7, 6))
    U = m.synthesize(c)
    assert U.shape == (7, 30, 3)
    assert np.allclose(m.project(U), c)
    assert np.allclose(m.project(U[0]), c[0])
    assert np.allclose(m.synthesize(np.zeros(6)), m.mean_.reshape(-1, 3))


def test_llse_recovers_exact_coefficients_of_model_data():
    m = ModeModel(6).fit(_frames(rank=12))
    rng = np.random.default_rng(5)
    c = rng.normal(size=(4, 6)) * np.sqrt(m.explained_variance_)
    U = m.synthesize(c).reshape(4, -1)
    # Only 5 nodes' x-y (10 DOFs) for 6 modes; Lambda_y is full rank here.
    dofs = (3 * np.array([0, 4, 9, 17, 25])[:, None] + np.array([0, 1])).ravel()
    est = m.llse(dofs)
    Uh = est(U[:, dofs])
    assert np.allclose(Uh.reshape(4, -1), U, atol=1e-9)
    assert np.allclose(m.project(Uh), c, atol=1e-9)
    # Many more observations than modes: Lambda_y is singular (rank 6) and the pseudo-inverse is used.
    many = np.arange(60)
    assert np.allclose(m.llse(many)(U[:, many]).reshape(4, -1), U, atol=1e-9)


def test_llse_with_every_dof_observed_returns_observations():
    rng = np.random.default_rng(7)
    D = 36
    cov = LowRankCovariance(rng.normal(size=(D + 5, D)))  # full rank
    mean = rng.normal(size=D)
    y = rng.normal(size=(3, D))
    Uh, post = llse(np.arange(D), y, cov, mean=mean)
    assert np.allclose(Uh.reshape(3, -1), y, atol=1e-9)
    assert np.allclose(post, 0, atol=1e-8)
    # The learned full sample covariance reproduces a training frame from all its DOFs.
    U = _frames(F=20, n=12)
    m = ModeModel(5).fit(U)
    assert np.allclose(m.llse(np.arange(36), "full")(U[3].ravel()), U[3], atol=1e-9)


def test_llse_matches_textbook_conditioning_and_noise():
    rng = np.random.default_rng(11)
    D, d = 30, 9
    B = rng.normal(size=(D, D))
    cov = LowRankCovariance(B)
    Sig = B.T @ B
    mean = rng.normal(size=D)
    o = rng.choice(D, d, replace=False)
    y = rng.normal(size=d)
    want = mean + Sig[:, o] @ np.linalg.solve(Sig[np.ix_(o, o)], y - mean[o])
    assert np.allclose(llse(o, y, cov, mean=mean)[0].ravel(), want)
    # With noise R: the information-form posterior mean (an independent formula).
    R = np.linspace(0.5, 2.0, d)
    H = np.zeros((d, D))
    H[np.arange(d), o] = 1
    Pinv = np.linalg.inv(Sig) + H.T @ np.diag(1 / R) @ H
    want_n = np.linalg.solve(Pinv, np.linalg.solve(Sig, mean) + H.T @ (y / R))
    est = LLSE.build(cov, o, mean=mean, noise=R)
    assert np.allclose(est(y).ravel(), want_n)
    assert np.allclose(est.posterior_matrix(), np.linalg.inv(Pinv), atol=1e-8)


def test_posterior_is_psd_and_shrinks_with_more_observations():
    m = ModeModel(8).fit(_frames(F=40, rank=15))
    for k in (None, "full"):
        cov = m.covariance(k)
        prev = cov.matrix()
        scale = np.abs(prev).max()
        for d in (3, 12, 30, 60):
            est = m.llse(np.arange(d), k)
            post = est.posterior_matrix()
            assert np.linalg.eigvalsh(post).min() > -1e-9 * scale
            assert np.linalg.eigvalsh(prev - post).min() > -1e-9 * scale  # Loewner order
            blocks = est.posterior_blocks()
            n = m.n_nodes_
            dense = np.stack([post[3 * i:3 * i + 3, 3 * i:3 * i + 3] for i in range(n)])
            assert np.allclose(blocks, dense, atol=1e-9 * scale)
            assert np.allclose(est.posterior_variance(), np.diagonal(post).reshape(n, 3))
            prev = post


def test_sum_covariance_adds_columns_and_blocks():
    rng = np.random.default_rng(0)
    a, b = LowRankCovariance(rng.normal(size=(3, 12))), LowRankCovariance(rng.normal(size=(5, 12)))
    s = SumCovariance(a, b)
    assert np.allclose(s.matrix(), a.matrix() + b.matrix())
    assert np.allclose(s.diag_blocks([1, 2]), a.diag_blocks([1, 2]) + b.diag_blocks([1, 2]))


def test_save_load_roundtrip(tmp_path):
    mesh = _strip_mesh(30)
    m = ModeModel(4).fit(_frames(), mesh=mesh)
    p = tmp_path / "modes.npz"
    m.save(p)
    r = ModeModel.load(p)
    for attr in ("mean_", "components_", "explained_variance_", "explained_variance_ratio_",
                 "full_components_", "full_variance_"):
        assert np.array_equal(getattr(r, attr), getattr(m, attr))
    assert r.topology_id_ == mesh.topology_id and r.n_nodes_ == 30 and r.n_modes == 4
    r.check_mesh(mesh)


def test_bad_inputs_get_clear_errors(tmp_path):
    U = _frames(F=12, n=10)
    with pytest.raises(ValueError, match="12 frame.*10 modes|cannot give 12 modes"):
        ModeModel(12).fit(U)
    bad = U.copy()
    bad[4, 2, 1] = np.nan
    with pytest.raises(ValueError, match=r"non-finite.*\(4, 7\)"):
        ModeModel(3).fit(bad)
    with pytest.raises(ValueError, match=r"shape \(F, n, 3\)"):
        ModeModel(3).fit(np.zeros((12, 10, 2)))
    m = ModeModel(3).fit(U)
    with pytest.raises(ValueError, match=r"out of range \[0, 30\)"):
        m.llse([0, 30])
    with pytest.raises(ValueError, match="repeats"):
        m.llse([1, 2, 2])
    with pytest.raises(ValueError, match=r"values must have shape \(2,\)"):
        m.llse([0, 1])(np.zeros(3))
    with pytest.raises(TopologyMismatchError, match="10 nodes but mesh"):
        m.check_mesh(_strip_mesh(12))
    with pytest.raises(TopologyMismatchError):
        ModeModel(3).fit(U, mesh=_strip_mesh(12))
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(b"not a zip at all")
    with pytest.raises(ModelFileError, match="corrupt"):
        ModeModel.load(corrupt)
    old = tmp_path / "old.npz"
    save_npz(old, "lipgen.ModeModel", 99, {"mean": np.zeros(3)})
    with pytest.raises(ModelFileError, match="schema version 99"):
        ModeModel.load(old)
    with pytest.raises(RuntimeError, match="not fitted"):
        ModeModel(2).synthesize([0, 0])
