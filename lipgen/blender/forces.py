"""Forces on chosen vertices, the live preview's unit responses, and reach goals.

The physics is linear, so the displacement of a force of magnitude ``a`` in direction ``d`` on
a fixed set of vertices is ``a * (d_x U_x + d_y U_y + d_z U_z)``, where ``U_x`` is the response to
a unit force along x on every chosen vertex. :class:`ForceResponses` solves for ``U_x, U_y, U_z``
and the response to unit forces along the vertex normals once per selection; every later
change of direction or magnitude in the preview is then a weighted sum, not a solve.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lipgen._validate import as_float_array, as_index_array
from lipgen.tol import tol

__all__ = ["force_field", "ForceResponses", "moved_nodes", "reach_goals", "ReachGoals"]


def _unit(direction) -> np.ndarray:
    d = as_float_array(direction, "direction", (3,))
    norm = float(np.linalg.norm(d))
    if norm <= tol.zero:
        raise ValueError(f"direction must be a non-zero vector, got {d.tolist()}")
    return d / norm


def force_field(n_nodes: int, nodes, magnitude: float, direction=None, normals=None) -> np.ndarray:
    """Nodal forces: ``magnitude`` on each of ``nodes``, along ``direction`` or the normals.

    Parameters
    ----------
    n_nodes : int
        Nodes in the mesh.
    nodes : (s,) int
        Nodes that receive the force.
    magnitude : float
        Force on each node (the physics' force unit; negative flips the direction).
    direction : (3,) float, optional
        One direction for all nodes (normalised here). Give this or ``normals``.
    normals : (n, 3) float, optional
        Unit vertex normals; each node is pushed along its own normal.

    Returns
    -------
    (n, 3) float
    """
    idx = as_index_array(nodes, "nodes", n_nodes, unique=True, allow_empty=False)
    F = np.zeros((n_nodes, 3))
    if (direction is None) == (normals is None):
        raise ValueError("give exactly one of direction (a vector) or normals (per vertex)")
    if direction is not None:
        F[idx] = float(magnitude) * _unit(direction)
    else:
        N = as_float_array(normals, "normals", (n_nodes, 3))
        F[idx] = float(magnitude) * N[idx]
    return F


class ForceResponses:
    """The displacements caused by unit forces on one selection of nodes.

    Parameters
    ----------
    physics : lipgen.fem.Physics
        Factorised physics of the mesh.
    nodes : (s,) int
        The selected nodes.
    normals : (n, 3) float
        Unit vertex normals of the rest mesh.

    Attributes
    ----------
    axes : (3, n, 3) float
        Responses to a unit force along x, y and z on every selected node.
    normal : (n, 3) float
        Response to a unit force along each selected node's normal.
    """

    def __init__(self, physics, nodes, normals) -> None:
        n = physics.mesh.n_nodes
        self.nodes = as_index_array(nodes, "nodes", n, unique=True, allow_empty=False)
        N = as_float_array(normals, "normals", (n, 3))
        F = np.zeros((4, n, 3))
        for axis in range(3):
            F[axis, self.nodes, axis] = 1.0
        F[3, self.nodes] = N[self.nodes]
        U = np.asarray(physics.displace(F))
        self.axes = U[:3]
        self.normal = U[3]

    def displacement(self, magnitude: float, direction=None, peak: bool = False) -> np.ndarray:
        """(n, 3) displacement for ``magnitude`` per node along ``direction`` (None: normals).

        With ``peak`` the magnitude is a length instead: the force is scaled so that the
        largest vertex displacement is ``|magnitude|`` mm (the sign still picks the direction).
        """
        if direction is None:
            U = self.normal.copy()
        else:
            U = np.tensordot(_unit(direction), self.axes, axes=(0, 0))
        if peak:
            top = float(np.linalg.norm(U, axis=1).max())
            if top <= tol.zero:
                raise ValueError("the force moves no vertex (are all the chosen vertices anchored?)")
            return U * (float(magnitude) / top)
        return U * float(magnitude)

    def force_scale(self, magnitude: float, direction=None, peak: bool = False) -> float:
        """The force on each node that :meth:`displacement` applies for these settings."""
        if not peak:
            return float(magnitude)
        U = self.displacement(1.0, direction)
        return float(magnitude) / float(np.linalg.norm(U, axis=1).max())


@dataclass(frozen=True)
class ReachGoals:
    """Goals for :meth:`lipgen.fem.Physics.reach`: nodes with their target displacements.

    Attributes
    ----------
    nodes : (g,) int
        Goal nodes.
    dofs : (3g,) int
        Their x, y, z degrees of freedom, node-major.
    values : (3g,) float
        Target displacement of each DOF (mm).
    skipped_anchors : (a,) int
        Requested goal nodes that were dropped because they are anchored (fixed to the head).
    """

    nodes: np.ndarray
    dofs: np.ndarray
    values: np.ndarray
    skipped_anchors: np.ndarray


def moved_nodes(before, after, threshold: float = 1e-4) -> np.ndarray:
    """Sorted nodes whose position changed by more than ``threshold`` (mm) from ``before``."""
    B = as_float_array(before, "before", (None, 3))
    A = as_float_array(after, "after", B.shape)
    return np.flatnonzero(np.linalg.norm(A - B, axis=1) > float(threshold)).astype(np.int64)


def reach_goals(rest, target, nodes, anchors=()) -> ReachGoals:
    """Goals that put ``nodes`` at their ``target`` positions (all three axes).

    Parameters
    ----------
    rest : (n, 3) float
        Rest positions (mm).
    target : (n, 3) float
        Wanted positions (mm); only the rows of ``nodes`` are used.
    nodes : (g,) int
        Goal nodes (moved by the artist, or held where they are).
    anchors : (a,) int
        Anchored nodes; they cannot move, so they are dropped from the goals.

    Raises
    ------
    ValueError
        If no goal is left: there is nothing to reach.
    """
    R = as_float_array(rest, "rest", (None, 3))
    T = as_float_array(target, "target", R.shape)
    n = len(R)
    goal = np.zeros(n, bool)
    goal[as_index_array(nodes, "nodes", n)] = True
    anchored = np.zeros(n, bool)
    anchored[as_index_array(anchors, "anchors", n)] = True
    skipped = np.flatnonzero(goal & anchored)
    goal &= ~anchored
    idx = np.flatnonzero(goal)
    if len(idx) == 0:
        raise ValueError(
            f"no reach goal among {n} vertices ({len(skipped)} requested goal(s) are anchors); move "
            "a few vertices of the reach shape key (not the anchors) first")
    dofs = (3 * idx[:, None] + np.arange(3)).ravel()
    return ReachGoals(idx, dofs, (T[idx] - R[idx]).ravel(), skipped)
