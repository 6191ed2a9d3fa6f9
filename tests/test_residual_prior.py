"""Choosing the combined model's residual prior and noise by cross-validated marginal likelihood."""

import numpy as np
import pytest

from lipgen import Physics, dofs, lip_mesh
from lipgen.modes.residual_prior import select_residual_prior


@pytest.fixture(scope="module")
def physics():
    return Physics(lip_mesh(0))


def _frames(physics, n_frames, residual_sd, noise_sd, seed=0):
    """Frames drawn from the combined model itself: 4 big modes + residual_sd² K_s⁻² + noise_sd² I."""
    rng = np.random.default_rng(seed)
    free = physics.free_dofs
    B = np.zeros((4, physics.n_dofs))
    sd = np.array([40.0, 30.0, 20.0, 10.0])[:, None]
    B[:, free] = np.linalg.qr(rng.normal(size=(len(free), 4)))[0].T * sd
    coef = rng.normal(size=(n_frames, 4))
    residual = np.asarray(physics.solve(rng.normal(size=(physics.n_dofs, n_frames)))).T  # cov K_s^-2
    U = coef @ B + residual_sd * residual + noise_sd * rng.normal(size=(n_frames, physics.n_dofs))
    U[:, physics.anchored_dofs] = 0.0
    return U


def test_recovers_the_residual_and_noise_variances_of_model_data(physics):
    # Residual and noise each contribute a comparable variance at the markers.
    o = dofs(physics.mesh.markers)
    P = np.asarray(physics.solve(np.asarray(physics.compliance_columns(o))))[o]
    residual_sd = 0.3 / np.sqrt(np.trace(P) / len(o))
    U = _frames(physics, 400, residual_sd, 0.3)
    sel = select_residual_prior(U, physics, n_modes=4)
    assert sel.kind == "force"  # the prior the data were drawn from
    assert sel.residual_variance == pytest.approx(residual_sd ** 2, rel=0.35)
    assert sel.noise_variance == pytest.approx(0.09, rel=0.35)
    assert set(sel.by_kind) == {"force", "energy"} and sel.n_folds == 5 and len(sel.dofs) == 48
    # Without noise the noise variance found is (close to) zero.
    clean = select_residual_prior(_frames(physics, 400, residual_sd, 0.0), physics, n_modes=4)
    assert clean.noise_variance < 0.01 * 0.09
    assert clean.residual_variance == pytest.approx(residual_sd ** 2, rel=0.35)


def test_bad_input(physics):
    U = _frames(physics, 30, 0.01, 0.0)
    with pytest.raises(ValueError, match="n_folds must be >= 2"):
        select_residual_prior(U, physics, n_modes=4, n_folds=1)
    with pytest.raises(ValueError, match="fewer than n_modes"):
        select_residual_prior(U[:12], physics, n_modes=10)
    with pytest.raises(ValueError, match="nodes but the physics mesh has"):
        select_residual_prior(U[:, :-3], physics, n_modes=4)
    with pytest.raises(ValueError, match="NaN|nan|finite"):
        select_residual_prior(np.full_like(U, np.nan), physics, n_modes=4)
