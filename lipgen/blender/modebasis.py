"""The modes a Blender rig drives, whatever they came from.

A rig shows one slider per mode. Blender clamps a shape key's value to its slider range, at
most [-10, 10], so a slider cannot carry a raw mode coefficient (which may be 30 for a wide
mouth). Each mode therefore has a *slider unit* (``scales``): the coefficient that a slider
value of 1 stands for. The mode's shape key stores ``scale * component``, so
``slider * (scale * component) == coefficient * component`` and the rig reproduces
:meth:`lipgen.modes.ModeModel.synthesize` exactly. For trained modes the unit is one standard
deviation of the training data; for modes built from the physics it is the amplitude that moves
the mode's largest vertex by 1 mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lipgen._validate import as_float_array
from lipgen.errors import TopologyMismatchError

__all__ = ["ModeBasis", "SLIDER_LIMIT"]

SLIDER_LIMIT = 10.0
"""Blender's widest shape-key slider range is [-10, 10]; values beyond it are clamped."""


def _readonly(a) -> np.ndarray:
    a = np.array(a, dtype=np.float64, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class ModeBasis:
    """A mean displacement plus ``k`` orthonormal modes over one mesh topology.

    Parameters
    ----------
    mean : (n, 3) float
        Displacement added at every frame (mm); zeros for modes built from the physics.
    components : (k, n, 3) float
        The modes, each of unit norm over its 3n entries.
    scales : (k,) float
        Slider units: the coefficient a slider value of 1 stands for (> 0).
    names : tuple of str
        One display name per mode.
    topology_id : str
        :attr:`lipgen.LipMesh.topology_id` of the mesh the modes belong to ("" if unknown).
    source : str
        Where the modes came from, for the user interface.
    """

    mean: np.ndarray
    components: np.ndarray
    scales: np.ndarray
    names: tuple[str, ...]
    topology_id: str = ""
    source: str = ""

    def __post_init__(self) -> None:
        comp = as_float_array(self.components, "components", (None, None, 3))
        k, n = comp.shape[:2]
        if k == 0:
            raise ValueError("a mode basis needs at least one mode, got components of shape "
                             f"{comp.shape}")
        mean = as_float_array(self.mean, "mean", (n, 3))
        scales = as_float_array(self.scales, "scales", (k,))
        if (scales <= 0).any():
            raise ValueError(f"scales must be positive, got {scales.tolist()}")
        names = tuple(str(s) for s in self.names)
        if len(names) != k:
            raise ValueError(f"names has {len(names)} entries for {k} modes")
        object.__setattr__(self, "components", _readonly(comp))
        object.__setattr__(self, "mean", _readonly(mean))
        object.__setattr__(self, "scales", _readonly(scales))
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "topology_id", str(self.topology_id))

    # ---- sizes -------------------------------------------------------------------------
    @property
    def n_modes(self) -> int:
        return int(self.components.shape[0])

    @property
    def n_nodes(self) -> int:
        return int(self.components.shape[1])

    # ---- what the rig stores -----------------------------------------------------------
    def offsets(self) -> np.ndarray:
        """(k, n, 3) displacement of each mode's shape key at slider value 1 (mm)."""
        return self.components * self.scales[:, None, None]

    def sliders(self, coefficients) -> np.ndarray:
        """Slider values for mode ``coefficients`` (``(k,)`` or ``(F, k)``)."""
        c = as_float_array(coefficients, "coefficients")
        if c.shape[-1:] != (self.n_modes,):
            raise ValueError(f"coefficients must have {self.n_modes} columns (one per mode), "
                             f"got shape {c.shape}")
        return c / self.scales

    def coefficients(self, sliders) -> np.ndarray:
        """Mode coefficients for slider values (``(k,)`` or ``(F, k)``)."""
        s = as_float_array(sliders, "sliders")
        if s.shape[-1:] != (self.n_modes,):
            raise ValueError(f"sliders must have {self.n_modes} columns, got shape {s.shape}")
        return s * self.scales

    def displacement(self, coefficients) -> np.ndarray:
        """``mean + coefficients @ components``: ``(n, 3)``, or ``(F, n, 3)`` for ``(F, k)``."""
        c = as_float_array(coefficients, "coefficients")
        if c.shape[-1:] != (self.n_modes,):
            raise ValueError(f"coefficients must have {self.n_modes} columns, got shape {c.shape}")
        flat = c @ self.components.reshape(self.n_modes, -1)
        return self.mean + flat.reshape(*c.shape[:-1], self.n_nodes, 3)

    def project(self, displacements) -> np.ndarray:
        """Mode coefficients of displacement fields: ``(n, 3)`` -> ``(k,)``, ``(F, n, 3)`` -> ``(F, k)``.

        The least-squares fit ``(U - mean) . components`` (the components are orthonormal).
        """
        U = as_float_array(displacements, "displacements")
        if U.shape[-2:] != (self.n_nodes, 3):
            raise ValueError(f"displacements must end in ({self.n_nodes}, 3) for these modes, "
                             f"got shape {U.shape}")
        X = (U - self.mean).reshape(*U.shape[:-2], -1)
        return X @ self.components.reshape(self.n_modes, -1).T

    def check_topology(self, topology_id: str, what: str = "this mesh") -> None:
        """Raise :class:`TopologyMismatchError` unless ``topology_id`` is the modes' own.

        Modes of unknown topology ("") are checked by node count only, by the caller.
        """
        if self.topology_id and topology_id != self.topology_id:
            raise TopologyMismatchError(
                f"the modes ({self.source or 'mode basis'}) were built for a mesh of topology "
                f"{self.topology_id} with {self.n_nodes} nodes, but {what} has topology "
                f"{topology_id}; modes only apply to the mesh they were trained on (same vertex "
                "count, order and faces). Build or train modes for this mesh instead.")

    # ---- constructors ------------------------------------------------------------------
    @classmethod
    def from_model(cls, model, source: str = "ModeModel", topology_id: str | None = None) -> ModeBasis:
        """The modes of a fitted :class:`lipgen.modes.ModeModel`; slider unit = one std dev."""
        comp = np.asarray(model.components_, dtype=np.float64)
        k = comp.shape[0]
        n = int(model.n_nodes_)
        var = np.asarray(getattr(model, "explained_variance_", np.ones(k)), dtype=np.float64)
        sd = np.sqrt(np.clip(var, 0.0, None))
        scales = np.where(np.isfinite(sd) & (sd > 0), sd, 1.0)
        topo = topology_id if topology_id is not None else str(getattr(model, "topology_id_", ""))
        return cls(np.asarray(model.mean_, float).reshape(n, 3), comp.reshape(k, n, 3), scales,
                   tuple(f"Mode {i + 1}" for i in range(k)), topo, source)

    @classmethod
    def fit(cls, frames, n_modes: int, mesh=None, source: str = "fitted") -> ModeBasis:
        """PCA modes of displacement ``frames`` ``(F, n, 3)`` through :class:`lipgen.modes.ModeModel`.

        ``mesh`` (a :class:`lipgen.LipMesh`) records the topology the modes belong to.
        """
        from lipgen.modes.model import ModeModel

        U = as_float_array(frames, "frames", (None, None, 3))
        model = ModeModel(n_modes=int(n_modes)).fit(U, mesh=mesh)
        return cls.from_model(model, source=source)

    def as_model(self) -> _BasisModel:
        """A read-only stand-in with a fitted :class:`~lipgen.modes.ModeModel`'s attributes
        (``mean_``, ``components_``, ``explained_variance_ = scales**2``, ``n_nodes_``,
        ``topology_id_``, ``check_mesh``, ``synthesize``), for :func:`lipgen.usd.export_usd`:
        USD blend-shape weights then equal the rig's slider values."""
        return _BasisModel(self)

    @classmethod
    def from_physics(cls, physics, n_modes: int) -> ModeBasis:
        """The ``n_modes`` softest deformations of the grounded shell.

        These are the eigenvectors of the grounded stiffness K_s with the smallest eigenvalues,
        found as the largest eigenvalues of the compliance K_s^-1 (Lanczos over
        :meth:`~lipgen.fem.Physics.solve`, which reuses the one factorisation). Anchored DOFs
        stay zero. Each slider unit moves the mode's largest vertex by 1 mm.
        """
        from scipy.sparse.linalg import LinearOperator, eigsh

        free = np.asarray(physics.free_dofs, dtype=np.int64)
        n = physics.mesh.n_nodes
        k = int(n_modes)
        if not 1 <= k < len(free):
            raise ValueError(f"n_modes must be in [1, {len(free) - 1}] for a mesh with "
                             f"{len(free)} free DOFs, got {n_modes}")

        def compliance(x):
            rhs = np.zeros((3 * n, 1))
            rhs[free, 0] = np.ravel(x)
            return np.asarray(physics.solve(rhs)).reshape(3 * n)[free]

        op = LinearOperator((len(free), len(free)), matvec=compliance, dtype=np.float64)
        vals, vecs = eigsh(op, k=k, which="LA", v0=np.ones(len(free)), tol=1e-12)
        order = np.argsort(-vals)
        comp = np.zeros((k, 3 * n))
        comp[:, free] = vecs[:, order].T
        comp /= np.linalg.norm(comp, axis=1, keepdims=True)
        # Deterministic signs: the largest entry of each mode is positive.
        peak = np.argmax(np.abs(comp), axis=1)
        comp *= np.sign(comp[np.arange(k), peak])[:, None]
        comp = comp.reshape(k, n, 3)
        scales = 1.0 / np.linalg.norm(comp, axis=2).max(axis=1)
        return cls(np.zeros((n, 3)), comp, scales, tuple(f"Soft {i + 1}" for i in range(k)),
                   physics.mesh.topology_id, "physics (softest modes)")


class _BasisModel:
    """What :meth:`ModeBasis.as_model` returns (see there)."""

    def __init__(self, basis: ModeBasis) -> None:
        self.mean_ = basis.mean.reshape(-1).copy()
        self.components_ = basis.components.reshape(basis.n_modes, -1).copy()
        self.explained_variance_ = basis.scales**2
        self.n_nodes_ = basis.n_nodes
        self.topology_id_ = basis.topology_id
        self._basis = basis

    def check_mesh(self, mesh) -> None:
        if mesh.n_nodes != self.n_nodes_:
            raise TopologyMismatchError(f"the modes have {self.n_nodes_} nodes but mesh "
                                        f"{mesh.name!r} has {mesh.n_nodes}")
        self._basis.check_topology(mesh.topology_id, f"mesh {mesh.name!r}")

    def synthesize(self, coef) -> np.ndarray:
        return self._basis.displacement(coef)
