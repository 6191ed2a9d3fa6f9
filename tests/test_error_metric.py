"""The one definition of the Table 5.1 error (lipgen.evaluate.metric), used by evaluate and table51."""

import numpy as np
import pytest

from lipgen.evaluate.metric import hidden_dofs, per_dof_error, relative_error


def test_error_per_hidden_dof_by_hand():
    ref = np.zeros((2, 2, 3))
    ref[0, 1] = [1.0, 2.0, 2.0]  # frame 0, node 1
    est = ref.copy()
    est[0, 1, 0] += 3.0  # error on hidden DOF 3
    est[1, 0, 0] += 100.0  # error on an observed DOF: not counted
    hid = hidden_dofs(np.arange(1, 6), observed=[0, 5])  # DOF 0 anchored is not free either
    assert hid.tolist() == [1, 2, 3, 4]
    assert per_dof_error(est, ref, hid) == pytest.approx(9.0 / 8)
    assert relative_error(est, ref, hid) == pytest.approx((9.0 / 8) / ((1 + 4) / 8))  # DOF 5 is observed
    assert relative_error(np.zeros_like(ref), ref, hid) == pytest.approx(1.0)  # no motion scores 1


def test_table51_and_evaluate_share_the_definition():
    """The experiment's row error equals the metric computed from its own estimate."""
    from lipgen import Physics, lip_mesh
    from lipgen.experiments.table51_protocol import _hidden, row_errors
    from lipgen.fem import dofs

    physics = Physics(lip_mesh(0))
    rng = np.random.default_rng(1)
    d = dofs(physics.mesh.markers, "yz")
    U = rng.normal(size=(5, physics.mesh.n_nodes * 3))

    def est(Y):
        return np.tile(Y.mean(axis=1, keepdims=True), (1, U.shape[1]))

    hid = _hidden(physics, d)
    assert not np.isin(hid, d).any() and not np.isin(hid, physics.anchored_dofs).any()
    X = est(U[:, d])
    assert row_errors(est, d, U, U, hid) == pytest.approx(np.mean((X[:, hid] - U[:, hid]) ** 2), rel=1e-12)
    assert row_errors(est, d, U, U, hid, relative=True) == pytest.approx(
        np.mean((X[:, hid] - U[:, hid]) ** 2) / np.mean(U[:, hid] ** 2), rel=1e-12)


def test_bad_shapes():
    with pytest.raises(ValueError, match="same frames and DOFs"):
        per_dof_error(np.zeros((2, 6)), np.zeros((3, 6)), [0])
    with pytest.raises(ValueError, match="no hidden DOFs"):
        per_dof_error(np.zeros((2, 6)), np.zeros((2, 6)), [])
