"""The truth subject's own physics: a thin volumetric layer of large-deformation elastic tissue.

The reconstruction model is lipgen.fem's linear thin shell (thesis §2.3). The truth must not be
(DESIGN.md, "avoid the inverse crime"), so the truth subject's lips are a different mechanical
model altogether:

- **geometry**: the surface mesh extruded inwards by a per-node thickness into one layer of
  prisms, each split into three tetrahedra (conforming by global node order;
  :func:`lipgen.subject.layer_build.build_layer`);
- **material**: St Venant-Kirchhoff, ``W = mu tr(E^2) + lambda/2 tr(E)^2`` with the Green strain
  ``E = (F^T F - I)/2`` (large rotations and stretches: geometrically nonlinear), per-face
  Young's modulus and Poisson's ratio per subject;
- **near-incompressibility**: a volume penalty ``kappa/2 (det F - 1)^2`` per tetrahedron, so a lip
  squeezed in its plane (a pucker) grows thicker;
- **contact between the lips**: a one-sided penalty on facing pairs of the inner contour, so the
  upper and lower lips press on each other instead of crossing;
- **the gum**: the inner side of the lower lip rests on the lower teeth and is pulled along by the
  jaw through stiff springs (the upper lip's inner side lies free on the upper teeth).

Each frame is an energy minimisation (L-BFGS started from a factorised positive semi-definite
tangent, with a line search: :meth:`Layer.solve`; on one BLAS thread), warm-started from the
previous frame, with the anchors and the jaw-carried border prescribed. In the small-strain limit
it agrees with the linear elasticity of its own Hessian at rest (tested), and it departs from it
at lip-sized strains (measured in the tests).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from lipgen.subject.layer_stiffness import (
    PatternCholesky,
    StiffnessPattern,
    cofactors,
    deformation_gradients,
    determinant,
    green_strain_stress,
    spd_solver,
    tet_hessians,
)

__all__ = ["Layer", "stvk_energy_density", "active_strain"]

log = logging.getLogger(__name__)

LBFGS_MEMORY = 5
"""Pairs the truth layer's L-BFGS keeps (:meth:`Layer.solve`). 3, 5, 8 and 12 were measured on 40
``hard`` frames (seed 6, with halving backtracking): 855, 865, 949 and 929 evaluations with 59, 53, 56
and 52 factorisations; none (the tangent alone, refactorised after every shortened step) 1105 and 114."""


def stvk_energy_density(F: np.ndarray, mu, lam) -> np.ndarray:
    """St Venant-Kirchhoff energy per unit rest volume of deformation gradients ``F`` (..., 3, 3)."""
    E = 0.5 * (np.swapaxes(F, -1, -2) @ F - np.eye(3))
    trE = np.trace(E, axis1=-2, axis2=-1)
    return mu * np.sum(E * E, axis=(-2, -1)) + 0.5 * lam * trE**2


def active_strain(fibres: np.ndarray, contraction: np.ndarray) -> np.ndarray:
    """(T, 3, 3) inverse isochoric active strains: fibres shortened by ``exp(-contraction)``.

    The active strain ``Fa = s f f^T + s^-1/2 (I - f f^T)``, ``s = exp(-contraction)``, shortens a
    muscle along its unit fibre direction ``f`` and widens it equally across, at constant volume
    (``det Fa = 1``; the active-strain approach of Nardinocchi & Teresi 2007, Ambrosi et al. 2011).
    The tissue's energy measures the elastic part ``F Fa^-1``, so a contracting, near-incompressible
    muscle shortens and thickens where it can.

    Parameters
    ----------
    fibres : (T, 3) float
        Unit fibre direction per tetrahedron.
    contraction : (T,) float
        Logarithmic fibre shortening (0: none; 0.22: the fibres at 80 % of their length).
    """
    f = np.asarray(fibres, float)
    c = np.asarray(contraction, float)[:, None, None]
    ff = f[:, :, None] * f[:, None, :]
    return np.exp(c) * ff + np.exp(-0.5 * c) * (np.eye(3) - ff)


@dataclass(frozen=True, eq=False)
class Layer:
    """A layer of St Venant-Kirchhoff tetrahedra under the lip surface (see the module docstring).

    Attributes
    ----------
    rest : (2n, 3) float
        Rest positions: the surface nodes, then their inner copies (mm).
    tets : (T, 4) int
    Dm_inv : (T, 3, 3) float
        Inverse rest edge matrices.
    volume : (T,) float
        Rest volumes (mm³).
    mu, lam, kappa : (T,) float
        Lamé parameters and volume penalty per tetrahedron.
    fixed : (2n,) bool
        Nodes whose positions are prescribed (anchors and their inner copies).
    contact_pairs : (p, 2) int
        [upper, lower] surface nodes that may touch but not cross (in y).
    contact_stiffness : float
    gum : (2n,) float
        Spring stiffness of each node to the jaw (the lower lip's inner side), per mm.
    K0 : (6n, 6n) sparse
        Stiffness at rest (linear elasticity with the volume penalty, plus the gum and contact
        springs): the solver's preconditioner, and the small-strain theory the tests compare with.
    """

    rest: np.ndarray
    tets: np.ndarray
    Dm_inv: np.ndarray
    volume: np.ndarray
    mu: np.ndarray
    lam: np.ndarray
    kappa: np.ndarray
    fixed: np.ndarray
    contact_pairs: np.ndarray
    contact_stiffness: float
    gum: np.ndarray
    K0: object = None
    cache: dict = field(default_factory=dict)
    iterations: list = field(default_factory=list)

    @property
    def n_surface(self) -> int:
        return len(self.rest) // 2

    def _dm_inv(self, active: np.ndarray | None) -> np.ndarray:
        """Inverse rest edge matrices, composed with an active strain's inverse ``active`` (T, 3, 3)."""
        return self.Dm_inv if active is None else self.Dm_inv @ active

    def energy_grad(self, x: np.ndarray, force: np.ndarray, gum_target: np.ndarray | None = None,
                    active: np.ndarray | None = None):
        """Total energy and its gradient (2n, 3) at positions ``x`` (2n, 3) under nodal ``force``.

        ``force`` (2n, 3) is a dead load (potential ``-f . (x - rest)``); ``gum_target`` (2n, 3) the
        positions the gum springs pull toward (their rest by default); ``active`` (T, 3, 3) the
        inverse of each tetrahedron's isochoric active strain (:func:`active_strain`), whose
        elastic part ``F Fa^-1`` the energy measures (a contracting muscle), or None.
        """
        return self._energy_grad(x, force, gum_target, self._kinematics(active))

    def _kinematics(self, active: np.ndarray | None):
        """What one solve's evaluations share, for ``active`` (see :meth:`energy_grad`): the
        deformation gradients at rest (9, T), the sparse map ``G`` (9T, 6n) from node displacements
        to the change of ``F`` (``F = F_rest + G u``; the energy's gradient is ``G^T`` of the
        stresses) and the shape gradients (4, 3, T). Rows are component-major (``F_ij`` of every
        tet, then the next component), so that each component is a contiguous array of the tets:
        the energy and the tangent then run over contiguous memory. Displacements, not positions,
        keep the sums small."""
        from scipy.sparse import csr_matrix

        Dm_inv = self._dm_inv(active)
        T, N = len(self.tets), len(self.rest)
        gN = np.concatenate([-Dm_inv.sum(axis=1, keepdims=True), Dm_inv], axis=1).transpose(1, 2, 0)
        if "strain_pattern" not in self.cache:  # row (i, j, t) of F: node a's coordinate i, a = 0..3
            cols = 3 * self.tets.T[None, None, :, :] + np.arange(3)[:, None, None, None]
            self.cache["strain_pattern"] = (np.broadcast_to(cols, (3, 3, 4, T)).transpose(0, 1, 3, 2).ravel(),
                                            np.arange(0, 36 * T + 1, 4))
        indices, indptr = self.cache["strain_pattern"]
        data = np.broadcast_to(gN.transpose(1, 2, 0)[None], (3, 3, T, 4)).ravel()
        G = csr_matrix((data, indices, indptr), shape=(9 * T, 3 * N))
        F_rest = deformation_gradients(self.rest, self.tets, Dm_inv).transpose(1, 2, 0).reshape(9, T)
        return np.ascontiguousarray(F_rest), G, np.ascontiguousarray(gN)

    def _deformation(self, x: np.ndarray, kinematics) -> np.ndarray:
        """(3, 3, T) deformation gradients at positions ``x`` (2n, 3), tets last."""
        F_rest, G, _ = kinematics
        return (F_rest.ravel() + G @ (x - self.rest).ravel()).reshape(3, 3, len(self.tets))

    def _energy_grad(self, x: np.ndarray, force: np.ndarray, gum_target: np.ndarray | None, kinematics):
        """:meth:`energy_grad` with :meth:`_kinematics` computed once per solve."""
        F = self._deformation(x, kinematics)
        E, trE, S = green_strain_stress(F, self.mu, self.lam)
        cof = cofactors(F)
        J1 = determinant(F, cof) - 1.0
        W = self.mu * np.einsum("abt,abt->t", E, E) + 0.5 * self.lam * trE**2 + 0.5 * self.kappa * J1**2
        stress = np.einsum("ikt,kjt->ijt", F, S) + (self.kappa * J1) * cof   # first Piola-Kirchhoff
        g = (kinematics[1].T @ (self.volume * stress).ravel()).reshape(-1, 3)
        energy = float(self.volume @ W)
        energy -= float(np.sum(force * (x - self.rest)))
        g -= force
        if self.gum.any():
            target = self.rest if gum_target is None else gum_target
            d = x - target
            energy += 0.5 * float(np.sum(self.gum[:, None] * d * d))
            g += self.gum[:, None] * d
        if len(self.contact_pairs):
            up, lo = self.contact_pairs[:, 0], self.contact_pairs[:, 1]
            gap = x[up, 1] - x[lo, 1]
            pen = np.minimum(gap, 0.0)
            energy += 0.5 * self.contact_stiffness * float(np.sum(pen * pen))
            push = self.contact_stiffness * pen
            g[:, 1] += np.bincount(up, push, len(x)) - np.bincount(lo, push, len(x))
        return energy, g

    def tangent(self, x: np.ndarray, psd: bool = True, active: np.ndarray | None = None,
                free_only: bool = False, kinematics=None, shift: float = 0.0):
        """Sparse stiffness at ``x``: the tets' energy Hessians, or with ``psd`` their positive
        semi-definite parts (a descent direction;
        :func:`~lipgen.subject.layer_stiffness.stress_derivative`), plus the springs as in K0 (the
        contact springs engaged where the lips touch); ``active`` as in :meth:`energy_grad`
        (``kinematics``, :meth:`_kinematics` of it, if the caller has them). ``shift`` times the
        diagonal of K0 is added to the diagonal (a relative regularisation).

        (6n, 6n) CSC, or the free nodes' block if ``free_only`` (the solver's matrix). Its sparsity
        pattern is the same at every ``x``: untouched contact springs are stored zeros.
        """
        key = "pattern_free" if free_only else "pattern_all"
        if key not in self.cache:
            on = np.repeat(~self.fixed, 3) if free_only else np.ones(3 * len(self.rest), bool)
            self.cache[key] = StiffnessPattern(self.tets, on, self.contact_pairs)
        kinematics = self._kinematics(active) if kinematics is None else kinematics
        K = tet_hessians(self._deformation(x, kinematics), kinematics[2], self.volume, self.mu, self.lam,
                         self.kappa, psd)
        up, lo = self.contact_pairs[:, 0], self.contact_pairs[:, 1]
        touching = self.contact_stiffness * (x[up, 1] < x[lo, 1])
        diagonal = np.repeat(self.gum, 3)
        if shift:
            diagonal = diagonal + shift * self.K0.diagonal()
        return self.cache[key].assemble(K, diagonal, touching)

    def solve(self, force: np.ndarray, prescribed: np.ndarray, x0: np.ndarray | None = None,
              gum_target: np.ndarray | None = None, tol: float = 1e-4, maxiter: int = 100,
              callback=None, active: np.ndarray | None = None) -> np.ndarray:
        """Equilibrium positions (2n, 3): minimise the energy over the free nodes.

        L-BFGS (:data:`LBFGS_MEMORY` pairs) whose initial inverse Hessian is the factorised positive
        semi-definite tangent (:meth:`tangent`) of a recent position, with a backtracking line search
        (Armijo; each trial at the minimum of the quadratic through the energy, its slope and the last
        trial, within [0.1, 0.5] of it), so the energy decreases monotonically. After a shortened step
        the tangent is factorised afresh at the new position and the memory cleared; the last
        factorisation is kept for the next call (frames are alike). Stops when the step is below
        ``tol`` mm.

        The tangent alone makes a Newton-like descent that converges linearly (it leaves out the
        compressive and volume-change parts of the Hessian, which are indefinite); the memory supplies
        their curvature along the path. On ``hard`` frames (the default seed, 36 frames; seeds 5, 6
        and 7, 30, 40 and 40 frames) it took 802, 705, 839 and 969 evaluations with 45, 60, 52 and
        76 factorisations, where the tangent alone (with halving backtracking, refactorised every
        fifth step) took 910, 851, 983 and 1344 with 97, 109, 119 and 161: half the CPU per frame
        (0.19 -> 0.10 s on the default seed). It stopped 2-4e-4 mm (largest node) from a solve to
        1e-8 mm on seeds 5-7, where the tangent alone stopped 4e-4 to 2e-3 mm from it.

        Each tangent is factorised by
        :class:`~lipgen.subject.layer_stiffness.PatternCholesky` (CHOLMOD when cvxopt is
        installed, analysed once per layer) and assembled in closed node form
        (:func:`~lipgen.subject.layer_stiffness.tet_hessians`): with the energy over contiguous
        per-component arrays, 0.06 s of CPU per frame on the default seed, against 0.13-0.16 s with
        SuperLU and the per-tet chain rule (the same steps; ``renders/examples/speed34``).

        Parameters
        ----------
        force : (2n, 3) float
            Dead loads on the nodes.
        prescribed : (2n, 3) float
            Positions of the fixed nodes (the others' entries are ignored).
        x0 : (2n, 3) float, optional
            Start (warm start: the previous frame); the rest by default.
        callback : callable, optional
            Called with the energy after each accepted step.
        active : (T, 3, 3) float, optional
            Inverse active strains (:func:`active_strain`): muscle contraction in the tissue.
        """
        if isinstance(maxiter, bool) or not isinstance(maxiter, (int, np.integer)) or maxiter < 1:
            raise ValueError(f"maxiter must be a positive integer (steps), got {maxiter!r}")
        if not (isinstance(tol, (int, float, np.floating)) and np.isfinite(tol) and tol > 0):
            raise ValueError(f"tol must be a positive number of mm (the smallest step), got {tol!r}")
        shape = self.rest.shape
        given = {"force": force, "prescribed": prescribed, "x0": x0, "gum_target": gum_target}
        for name, value in given.items():
            if value is not None and np.shape(value) != shape:
                raise ValueError(f"{name} must be {shape} like the layer's nodes, got shape "
                                 f"{np.shape(value)}")
        free = ~self.fixed
        x = (self.rest if x0 is None else np.asarray(x0, float)).copy()
        x[self.fixed] = prescribed[self.fixed]
        kinematics = self._kinematics(active)
        solve = self.cache.get("last", self._factor())  # the latest tangent: frames are alike
        e, g = self._energy_grad(x, force, gum_target, kinematics)
        memory: list = []      # L-BFGS pairs (s, y, 1 / y.s), oldest first
        for it in range(maxiter):  # noqa: B007 (the count is recorded after the loop)
            step = -_lbfgs_direction(g[free].ravel(), memory, solve).reshape(-1, 3)
            slope = float(np.sum(g[free] * step))
            if not slope < 0:   # the memory's curvature misleads: the tangent's step
                memory.clear()
                step = -solve(g[free].ravel()).reshape(-1, 3)
                slope = float(np.sum(g[free] * step))
            alpha, trial = 1.0, x.copy()
            while True:
                trial[free] = x[free] + alpha * step
                e_new, g_new = self._energy_grad(trial, force, gum_target, kinematics)
                if e_new <= e + 1e-4 * alpha * slope or alpha < 1e-6:
                    break
                curvature = e_new - e - slope * alpha
                guess = -slope * alpha * alpha / (2.0 * curvature) if curvature > 0 else 0.5 * alpha
                alpha = min(max(guess, 0.1 * alpha), 0.5 * alpha)
            if e_new > e:  # no decrease possible at this precision: converged
                break
            s_k = (alpha * step).ravel()
            y_k = (g_new[free] - g[free]).ravel()
            x, e, g = trial, e_new, g_new
            if callback is not None:
                callback(e)
            if alpha * np.abs(step).max() < tol:
                break
            if alpha < 1.0:  # the tangent is stale: a new one, and a memory that starts from it
                solve = self._factor(x, kinematics)
                self.cache["last"] = solve
                memory.clear()
            elif (sy := float(s_k @ y_k)) > 1e-12 * float(s_k @ s_k):  # positive curvature only
                memory.append((s_k, y_k, 1.0 / sy))
                del memory[:-LBFGS_MEMORY]
        else:
            log.warning("truth layer: no equilibrium after %d steps (last step %.2g mm)", maxiter,
                        alpha * np.abs(step).max())
        self.iterations.append(it + 1)
        return x

    def use_factorisation(self, method: str) -> None:
        """Factorise the tangents by ``method`` from now on (``"auto"``, ``"cholmod"`` or ``"superlu"``;
        :class:`~lipgen.subject.layer_stiffness.PatternCholesky`): to compare them, or to leave out
        GPL code at run time. The equilibria agree to rounding; the bytes do not."""
        if method not in PatternCholesky.METHODS:
            raise ValueError(f"method must be one of {PatternCholesky.METHODS}, got {method!r}")
        self.cache["factorisation"] = method
        self.cache.pop("cholesky", None)
        self.restart()

    def restart(self) -> None:
        """The next :meth:`solve` starts from the rest stiffness, not from the last call's tangent: a
        sequence solved after it gives the same bytes however many were solved before."""
        self.cache.pop("last", None)

    def _factor(self, x: np.ndarray | None = None, kinematics=None):
        """A solver with the free block of K0 (``x`` None, cached) or of the positive semi-definite
        tangent at ``x`` (:meth:`tangent`; ``kinematics`` as there), factorised in the order
        analysed once per layer (:class:`~lipgen.subject.layer_stiffness.PatternCholesky`). A
        tangent's solver is valid until the next tangent is factorised."""
        if x is not None:
            K = self.tangent(x, free_only=True, kinematics=kinematics, shift=1e-9)
            if "cholesky" not in self.cache:   # the pattern is fixed: analyse it once
                self.cache["cholesky"] = PatternCholesky(K, self.cache.get("factorisation", "auto"))
            try:
                return self.cache["cholesky"].factor(K)
            except np.linalg.LinAlgError as exc:   # rounding in a nearly singular tangent: any SPD start does
                log.warning("truth layer: %s; this step starts from the rest stiffness", exc)
        if "solve" not in self.cache:
            dof_free = np.repeat(~self.fixed, 3)
            self.cache["solve"] = spd_solver(self.K0[dof_free][:, dof_free])
        return self.cache["solve"]


def _lbfgs_direction(g: np.ndarray, memory: list, solve) -> np.ndarray:
    """The L-BFGS inverse-Hessian estimate times ``g`` (the two-loop recursion, Nocedal & Wright
    Algorithm 7.4), with ``solve`` (a factorised tangent) as the initial inverse Hessian and
    ``memory`` the pairs (s, y, 1 / y.s), oldest first. It maps the newest ``y`` to its ``s``."""
    q = g.copy()
    alphas = []
    for s, y, rho in reversed(memory):
        a = rho * float(s @ q)
        q -= a * y
        alphas.append(a)
    r = solve(q)
    for (s, y, rho), a in zip(memory, reversed(alphas), strict=True):
        r += (a - rho * float(y @ r)) * s
    return r
