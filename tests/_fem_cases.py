"""Small meshes shared by the physics tests."""

import numpy as np

from lipgen.fem import cholmod_available
from lipgen.fem.solver import cholespy_available
from lipgen.mesh.lipmesh import LipMesh

SOLVERS = (["superlu"] + (["cholmod"] if cholmod_available() else [])
           + (["cholespy"] if cholespy_available() else []))


def grid(nx=6, ny=5, bend=0.15, jitter=0.0, seed=0):
    """A sheet over [0, nx-1] x [0, ny-1], bent as z = bend * (x - c)^2 (bend=0: flat)."""
    x, y = np.meshgrid(np.arange(nx, dtype=float), np.arange(ny, dtype=float))
    V = np.c_[x.ravel(), y.ravel(), np.zeros(nx * ny)]
    if jitter:
        V[:, :2] += np.random.default_rng(seed).uniform(-jitter, jitter, (nx * ny, 2))
    V[:, 2] = bend * (V[:, 0] - (nx - 1) / 2) ** 2
    idx = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    return V, np.r_[np.c_[a, b, d], np.c_[a, d, c]], idx


def bent_mesh(**kw):
    V, F, idx = grid(**kw)
    return LipMesh(V, F, anchors=idx[0, :3])  # three nodes of the bottom edge
