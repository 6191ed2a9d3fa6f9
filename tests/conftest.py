"""Fixtures shared by more than one test module."""

import numpy as np
import pytest

from lipgen import Physics, dofs, lip_mesh
from lipgen.modes.model import ModeModel


@pytest.fixture(scope="module")
def usd_mesh():
    return lip_mesh(0)


@pytest.fixture(scope="module")
def usd_fitted(usd_mesh):
    """A ModeModel trained as the thesis did (least-strain fields reaching random marker goals,
    through the FEM), and the weights of 24 held-out frames."""
    rng = np.random.default_rng(7)
    physics = Physics(usd_mesh)
    model = ModeModel(n_modes=10).fit_from_markers(physics, rng.normal(scale=2.0, size=(80, 16, 3)))
    held_out, _ = physics.reach(dofs(usd_mesh.markers), rng.normal(scale=2.0, size=(24, 48)))
    return model, model.project(held_out)
