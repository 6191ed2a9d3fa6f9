"""Assembly reuses K's sparsity pattern per topology (issue 22): same matrix as scipy's COO path."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

import lipgen
from lipgen.fem import assembly
from lipgen.fem.element import element_stiffness


def _coo_reference(mesh, E):
    ke = element_stiffness(mesh.vertices[mesh.faces], assembly.face_stiffness(mesh, E), 0.01, "thesis")
    dof = assembly.element_dofs(mesh.faces)
    rows, cols = np.repeat(dof, 9, axis=1).ravel(), np.tile(dof, (1, 9)).ravel()
    return sp.coo_matrix((ke.ravel(), (rows, cols)), shape=(mesh.n_dofs,) * 2).tocsr()


def test_first_second_and_later_assemblies_match_scipy():
    mesh = lipgen.lip_mesh(0)
    assembly._PATTERNS.clear()
    rng = np.random.default_rng(0)
    for _ in range(3):  # the pattern built, then reused; a new E each time
        E = rng.uniform(0.5, 2.0, mesh.n_faces)
        K = assembly.assemble_stiffness(mesh, E)
        ref = _coo_reference(mesh, E)
        assert K.shape == ref.shape and K.nnz == ref.nnz
        assert abs(K - ref).max() <= 1e-12 * abs(ref).max()
        assert K.has_sorted_indices
    assert len(assembly._PATTERNS) == 1


def test_pattern_is_per_topology_and_bounded():
    assembly._PATTERNS.clear()
    meshes = [lipgen.lip_mesh(0), lipgen.lip_mesh(0, anchor_border=False), lipgen.lip_mesh(1)]
    for mesh in meshes + meshes:
        K = assembly.assemble_stiffness(mesh)
        assert abs(K - _coo_reference(mesh, None)).max() <= 1e-12 * abs(K).max()
    assert len(assembly._PATTERNS) <= assembly._PATTERNS_KEPT
    # a kept K is not aliased by the next assembly of the same topology
    a = assembly.assemble_stiffness(meshes[2])
    before = a.copy()
    assembly.assemble_stiffness(meshes[2], 3.0)
    assert abs(a - before).max() == 0


def test_same_input_same_bits():
    """Duplicates are summed in one fixed order: a re-assembly is bitwise the first one."""
    mesh = lipgen.lip_mesh(1)
    assembly._PATTERNS.clear()
    first = assembly.assemble_stiffness(mesh)
    again = assembly.assemble_stiffness(mesh)
    assert (first != again).nnz == 0
    assert np.array_equal(first.indptr, again.indptr) and np.array_equal(first.indices, again.indices)
