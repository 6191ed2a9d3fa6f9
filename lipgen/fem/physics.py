"""The lip physics: K assembled, anchors grounded, K_s factorised once (thesis §2.3-2.4, §4.1).

Degree-of-freedom vectors are node-major ``(x0, y0, z0, x1, ...)``, length 3n. Anchored DOFs are
removed to ground K (eq 2.15); everywhere they appear in an output they are zero, and forces on
them are absorbed by the ground (ignored).
"""

from __future__ import annotations

import logging
from collections import OrderedDict

import numpy as np
import scipy.linalg as sla

from lipgen._validate import as_float_array, as_index_array
from lipgen.fem.assembly import assemble_stiffness, check_grounding, face_stiffness
from lipgen.fem.element import OUT_OF_PLANE
from lipgen.fem.reach import EnergyPlan, ForcePlan, energy_plan, force_plan
from lipgen.fem.solver import factorize
from lipgen.mesh.lipmesh import LipMesh

__all__ = ["Physics", "dofs"]

log = logging.getLogger(__name__)

_AXES = "xyz"
_REACH_CACHE = 4  # dof sets kept; each holds two (3n, d) arrays


def dofs(nodes, axes: str = "xyz", n_nodes: int | None = None) -> np.ndarray:
    """Indices into the node-major 3n DOF vector.

    Parameters
    ----------
    nodes : int or (k,) int
        Node indices.
    axes : str
        Which axes of each node, a subset of ``"xyz"`` in any order (e.g. ``"z"`` or ``"xy"``).
    n_nodes : int, optional
        If given, node indices are checked against it.

    Returns
    -------
    (k * len(axes),) int64
        ``3 * node + axis``, node by node, axes in the order given.
    """
    if not isinstance(axes, str) or not axes or set(axes) - set(_AXES) or len(set(axes)) != len(axes):
        raise ValueError(f"axes must be a non-empty string of distinct letters from 'xyz', got {axes!r}")
    nodes = np.atleast_1d(np.asarray(nodes))
    upper = np.iinfo(np.int64).max // 3 if n_nodes is None else int(n_nodes)
    nodes = as_index_array(nodes, "nodes", upper)
    ax = np.array([_AXES.index(a) for a in axes], np.int64)
    return (3 * nodes[:, None] + ax).ravel()




class Physics:
    """Thin-shell FEM lips: forces to displacements and displacement goals to least-norm forces.

    Parameters
    ----------
    mesh : LipMesh
        The mesh; its ``anchors`` are grounded.
    stiffness : None, mapping or (m,) float
        Per-region E (``{"lip": 1.0, ...}``, overriding :data:`~lipgen.fem.DEFAULT_STIFFNESS`) or
        one E per face.
    poisson : float
        Poisson's ratio ν (the thesis: 0.01).
    out_of_plane : {"thesis", "laplacian"}
        Out-of-plane block: eq 2.13 as printed (default) or its shape-aware variant.
    solver : {"auto", "cholmod", "cholespy", "superlu"}
        Sparse factorisation (see :mod:`lipgen.fem.solver`).

    Attributes
    ----------
    mesh : LipMesh
    E : (m,) float
        Per-face elastic modulus.
    K : (3n, 3n) scipy.sparse.csr_matrix
        Ungrounded global stiffness (eq 2.8).
    free_dofs : (3n - 3a,) int64
        DOFs that are not anchored, ascending.
    anchored_dofs : (3a,) int64
    solver : str
        The backend actually used.

    Raises
    ------
    SingularStiffnessError
        If the anchors cannot hold the mesh (none, a loose piece, a free rigid motion) or the
        factorisation finds K_s numerically singular.
    """

    def __init__(self, mesh: LipMesh, stiffness=None, poisson: float = 0.01, *,
                 out_of_plane: str = "thesis", solver: str = "auto") -> None:
        if not isinstance(mesh, LipMesh):
            raise TypeError(f"mesh must be a lipgen.LipMesh, got {type(mesh).__name__}")
        if out_of_plane not in OUT_OF_PLANE:
            raise ValueError(f"out_of_plane must be one of {OUT_OF_PLANE}, got {out_of_plane!r}")
        self.mesh = mesh
        self.poisson = float(poisson)
        self.out_of_plane = out_of_plane
        self.E = face_stiffness(mesh, stiffness)
        self.E.setflags(write=False)
        self.K = assemble_stiffness(mesh, self.E, self.poisson, out_of_plane)
        check_grounding(mesh, self.K)
        anchored = np.zeros(mesh.n_dofs, bool)
        anchored[(3 * mesh.anchors[:, None] + np.arange(3)).ravel()] = True
        self.free_dofs = np.flatnonzero(~anchored)
        self.anchored_dofs = np.flatnonzero(anchored)
        self._is_free = ~anchored
        Ks = self.K[self.free_dofs][:, self.free_dofs]
        self._factor = factorize(Ks, solver)
        self.solver = self._factor.method
        self._plans: OrderedDict[tuple, ForcePlan | EnergyPlan] = OrderedDict()
        log.info("physics for %r: %d nodes, %d faces, %d free DOFs, solver %s", mesh.name,
                 mesh.n_nodes, mesh.n_faces, len(self.free_dofs), self.solver)

    # ---- sizes -------------------------------------------------------------------------------
    @property
    def n_nodes(self) -> int:
        return self.mesh.n_nodes

    @property
    def n_dofs(self) -> int:
        return self.mesh.n_dofs

    @property
    def K_s(self):
        """The grounded stiffness (free x free), sparse CSR."""
        return self.K[self.free_dofs][:, self.free_dofs]

    # ---- solves ------------------------------------------------------------------------------
    def solve(self, rhs) -> np.ndarray:
        """K_s⁻¹ applied to a 3n-row array (eq 2.15).

        Parameters
        ----------
        rhs : (3n,) or (3n, k) float
            Forces, node-major. Rows of anchored DOFs are ignored (the ground takes them).

        Returns
        -------
        (3n,) or (3n, k) float
            Displacements; anchored rows are zero.
        """
        n3 = self.n_dofs
        rhs = as_float_array(rhs, "rhs")
        if rhs.ndim not in (1, 2) or rhs.shape[0] != n3:
            raise ValueError(f"rhs must have shape ({n3},) or ({n3}, k) (node-major DOFs of a "
                             f"{self.n_nodes}-node mesh), got {rhs.shape}")
        out = np.zeros(rhs.shape)
        out[self.free_dofs] = self._factor.solve(rhs[self.free_dofs])
        return out

    def displace(self, F) -> np.ndarray:
        """Displacements under nodal forces: U = K_s⁻¹ F (eq 2.15).

        Parameters
        ----------
        F : (n, 3) or (b, n, 3) float
            Forces per node (any units consistent with E), batched over b.

        Returns
        -------
        (n, 3) or (b, n, 3) float
            Displacements in mm; anchors do not move.
        """
        F = as_float_array(F, "F")
        n = self.n_nodes
        if F.shape[-2:] != (n, 3) or F.ndim not in (2, 3):
            raise ValueError(f"F must have shape ({n}, 3) or (b, {n}, 3) for this {n}-node mesh, "
                             f"got {F.shape}")
        cols = F.reshape(-1, 3 * n).T
        U = self.solve(cols)
        return U.T.reshape(F.shape)

    def strain_energy(self, U) -> float | np.ndarray:
        """½ Uᵀ K U for ``U`` of shape (n, 3) (a float) or (b, n, 3) (shape (b,))."""
        U = as_float_array(U, "U")
        n = self.n_nodes
        if U.shape[-2:] != (n, 3) or U.ndim not in (2, 3):
            raise ValueError(f"U must have shape ({n}, 3) or (b, {n}, 3), got {U.shape}")
        X = U.reshape(-1, 3 * n).T
        e = 0.5 * np.einsum("ib,ib->b", X, self.K @ X)
        return float(e[0]) if U.ndim == 2 else e

    # ---- goals (eq 4.3) ----------------------------------------------------------------------
    def _goal_dofs(self, dofs_, name: str = "dofs") -> np.ndarray:
        d = as_index_array(dofs_, name, self.n_dofs, unique=True, allow_empty=False)
        held = ~self._is_free[d]
        if held.any():
            bad = d[held]
            raise ValueError(f"{name} include {int(held.sum())} DOF(s) of anchored nodes, e.g. DOF "
                             f"{int(bad[0])} (node {int(bad[0]) // 3}); anchored nodes cannot move, "
                             f"so drop these goals (anchors are {self.mesh.anchors[:10].tolist()})")
        return d

    def compliance_columns(self, dofs_) -> np.ndarray:
        """Columns of K_s⁻¹ for the given DOFs, by solves (no inverse is formed).

        Parameters
        ----------
        dofs_ : (d,) int
            Distinct, non-anchored DOF indices into the 3n vector.

        Returns
        -------
        (3n, d) float
            Column j is the displacement under a unit force on ``dofs_[j]``; anchored rows zero.
        """
        d = self._goal_dofs(dofs_)
        rhs = np.zeros((self.n_dofs, len(d)))
        rhs[d, np.arange(len(d))] = 1.0
        return self.solve(rhs)

    def _free_compliance(self, d: np.ndarray) -> np.ndarray:
        """The free rows of :meth:`compliance_columns` (checked ``d``), (3n - 3a, d), Fortran order."""
        unit = np.zeros((len(self.free_dofs), len(d)), order="F")
        unit[np.searchsorted(self.free_dofs, d), np.arange(len(d))] = 1.0
        return self._factor.solve(unit)

    def _plan(self, d: np.ndarray) -> ForcePlan:
        key = tuple(int(i) for i in d)
        plan = self._plans.get(key)
        if plan is not None:
            self._plans.move_to_end(key)
            return plan
        plan = force_plan(self._factor, self._free_compliance(d), self.free_dofs, self.n_dofs)
        self._plans[key] = plan
        if len(self._plans) > _REACH_CACHE:
            self._plans.popitem(last=False)
        return plan

    def reach(self, dofs_, values, objective: str = "force") -> tuple[np.ndarray, np.ndarray]:
        """The displacement field that reaches displacement goals, and the forces causing it.

        ``objective="force"`` (the thesis's eq 4.3, the default): the least-norm force,
        minimising FᵀF subject to (K_s⁻¹ F)[dofs_] = values (Appendix A), i.e.
        F = K_c⁻ᵀ (K_c⁻¹ K_c⁻ᵀ)⁻¹ U_g, then U = K_s⁻¹ F. It spreads force over every node, so the
        field can overshoot the goals (a free lip edge moves further than its markers).

        ``objective="energy"``: the least strain energy ½UᵀK_sU among fields that reach the goals;
        its forces act on the goal DOFs only, F = P C⁻¹ U_g with C = K_s⁻¹[dofs_, dofs_], and
        U = K_s⁻¹ F. No node moves further than the physics needs.

        The work per DOF set (2d solves and a QR or a Cholesky) is cached, so many frames with
        the same goal DOFs cost one matrix product each.

        Parameters
        ----------
        dofs_ : (d,) int
            Goal DOFs, indices into the node-major 3n vector (see :func:`dofs`); a goal may cover
            only some axes of a node. Distinct, not on anchored nodes.
        values : (d,) or (b, d) float
            Goal displacements in mm (b frames).
        objective : {"force", "energy"}
            What the field minimises (see above).

        Returns
        -------
        U, F : (n, 3) each, or (b, n, 3) each for batched values
            Displacements (equal to the goals at ``dofs_``) and the forces that cause them.
        """
        if objective not in ("force", "energy"):
            raise ValueError(f"objective must be 'force' (least-norm force, eq 4.3) or 'energy' (least "
                             f"strain energy), got {objective!r}")
        d = self._goal_dofs(dofs_)
        vals = as_float_array(values, "values")
        if vals.ndim not in (1, 2) or vals.shape[-1] != len(d):
            raise ValueError(f"values must have shape ({len(d)},) or (b, {len(d)}) for {len(d)} goal "
                             f"DOFs, got {vals.shape}")
        if objective == "energy":
            return self._reach_energy(d, vals)
        plan = self._plan(d)
        alpha = sla.solve_triangular(plan.R, vals.reshape(-1, len(d)).T, trans="T")  # R⁻ᵀ U_g
        n = self.n_nodes
        U = (plan.Z @ alpha).T.reshape(-1, n, 3)
        F = (plan.Q @ alpha).T.reshape(-1, n, 3)
        if vals.ndim == 1:
            return U[0], F[0]
        return U, F

    def _reach_energy(self, d: np.ndarray, vals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = ("energy", *(int(i) for i in d))
        plan = self._plans.get(key)
        if plan is None:
            plan = energy_plan(self.compliance_columns(d), d)
            self._plans[key] = plan
            if len(self._plans) > _REACH_CACHE:
                self._plans.popitem(last=False)
        S, L = plan.S, plan.L
        lam = sla.cho_solve((L, True), vals.reshape(-1, len(d)).T)  # C⁻¹ U_g, (d, b)
        n = self.n_nodes
        U = (S @ lam).T.reshape(-1, n, 3)
        F = np.zeros((lam.shape[1], 3 * n))
        F[:, d] = lam.T
        F = F.reshape(-1, n, 3)
        if vals.ndim == 1:
            return U[0], F[0]
        return U, F

    # ---- relinearisation (§2.4) --------------------------------------------------------------
    def relinearized(self, U) -> Physics:
        """The physics rebuilt at the deformed geometry ``mesh.vertices + U`` (same E, ν, anchors).

        Raises :class:`~lipgen.errors.MeshError` if the displacement collapses a face.
        """
        U = as_float_array(U, "U", (self.n_nodes, 3))
        return Physics(self.mesh.with_vertices(self.mesh.vertices + U), self.E, self.poisson,
                       out_of_plane=self.out_of_plane, solver=self.solver)

    def to_rest_state(self, dofs_, values) -> Physics:
        """Deform to a rest state with :meth:`reach` and re-linearise there (thesis §2.4, Fig 4-1).

        Parameters
        ----------
        dofs_ : (d,) int
        values : (d,) float
            Displacement goals that take the initial mesh to the rest state.
        """
        vals = as_float_array(values, "values")
        if vals.ndim != 1:
            raise ValueError(f"a rest state takes one set of goals, values of shape (d,), got {vals.shape}")
        U, _ = self.reach(dofs_, vals)
        return self.relinearized(U)

    def __reduce__(self):
        # The sparse factor cannot be pickled; a copy (e.g. sent to a worker process) is rebuilt
        # and factorised again from the mesh and the per-face E.
        return (_rebuild, (self.mesh, np.array(self.E), self.poisson, self.out_of_plane))

    def __repr__(self) -> str:
        return (f"Physics(mesh={self.mesh.name!r}, n_nodes={self.n_nodes}, n_faces={self.mesh.n_faces}, "
                f"free_dofs={len(self.free_dofs)}, solver={self.solver!r})")


def _rebuild(mesh: LipMesh, E: np.ndarray, poisson: float, out_of_plane: str) -> Physics:
    """Unpickle a :class:`Physics` (the solver is chosen afresh on the receiving side)."""
    return Physics(mesh, E, poisson, out_of_plane=out_of_plane)
