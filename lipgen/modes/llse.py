"""Linear least-squares estimation (LLSE, thesis eq 4.7) of a whole displacement field.

Given a prior covariance Λ of the 3n-vector of nodal displacements and its mean x̄, the
estimate of every DOF from an observed subset ``y`` (whole points, or only some axes: x-y for a
frontal view, y-z for a profile) is

    x̂ = x̄ + Λ[:, o] (Λ[o, o] + R)⁺ (y − x̄[o])

with R the observation-noise variance (zero by default) and ⁺ a pseudo-inverse where Λ[o, o] is
singular. The posterior covariance is Λ − Λ[:, o] (Λ[o, o] + R)⁺ Λ[o, :].

A covariance is any object with ``n_dofs`` and ``columns(dofs) -> (3n, d)`` (the columns
Λ[:, dofs]) and ``diag_blocks(nodes) -> (q, 3, 3)``; three are provided:

- :class:`LowRankCovariance`: Λ = Bᵀ B from a factor B (r, 3n): learned modes or the full
  sample covariance (:meth:`lipgen.modes.ModeModel.covariance`);
- :class:`PhysicsCovariance`: Λ = s · K_s⁻² (eq 4.5), the covariance of displacements under IID
  unit forces, or Λ = s · K_s⁻¹ (strain energy as the negative log-prior); its columns come from
  sparse solves, never from a dense inverse;
- :class:`SumCovariance`: the sum of independent parts (learned prior + physical residual).

:class:`LLSE` precomputes the gain for one set of observed DOFs, so that reconstructing a batch
of frames is a single matrix product.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lipgen._validate import as_float_array, as_index_array
from lipgen.tol import tol

__all__ = ["LowRankCovariance", "PhysicsCovariance", "SumCovariance", "LLSE", "llse", "pinvh"]


def _node_dofs(nodes: np.ndarray) -> np.ndarray:
    return (3 * np.asarray(nodes, np.int64)[:, None] + np.arange(3)).ravel()


def _nodes_arg(nodes, n_nodes: int) -> np.ndarray:
    if nodes is None:
        return np.arange(n_nodes)
    return as_index_array(nodes, "nodes", n_nodes)


def pinvh(S: np.ndarray, rtol: float | None = None) -> np.ndarray:
    """Pseudo-inverse of a symmetric positive semidefinite matrix by eigendecomposition.

    Eigenvalues below ``rtol`` times the largest (default ``tol.rank``) are treated as zero.
    """
    rtol = tol.rank if rtol is None else rtol
    S = 0.5 * (S + S.T)
    w, V = np.linalg.eigh(S)
    top = w.max() if w.size else 0.0
    if top <= 0:
        return np.zeros_like(S)
    keep = w > rtol * top
    Vk = V[:, keep]
    return (Vk / w[keep]) @ Vk.T


class LowRankCovariance:
    """Λ = Bᵀ B for a factor ``B`` of shape (r, 3n).

    For modes with orthonormal rows ``S`` and variances ``λ``, ``B = sqrt(λ)[:, None] * S``.
    """

    def __init__(self, factor: np.ndarray):
        B = as_float_array(factor, "factor", (None, None))
        if B.shape[1] % 3:
            raise ValueError(f"factor must have 3n columns (x, y, z per node), got shape {B.shape}")
        self.factor = B
        self.n_dofs = B.shape[1]

    @property
    def rank_bound(self) -> int:
        return self.factor.shape[0]

    def columns(self, dofs) -> np.ndarray:
        """(3n, d): the columns Λ[:, dofs]."""
        dofs = as_index_array(dofs, "dofs", self.n_dofs)
        return self.factor.T @ self.factor[:, dofs]

    def diag_blocks(self, nodes=None) -> np.ndarray:
        """(q, 3, 3): the 3x3 diagonal blocks of Λ for ``nodes`` (all nodes by default)."""
        nodes = _nodes_arg(nodes, self.n_dofs // 3)
        Bn = self.factor.reshape(self.factor.shape[0], -1, 3)[:, nodes, :]
        return np.einsum("rqa,rqb->qab", Bn, Bn)

    def matrix(self) -> np.ndarray:
        """(3n, 3n): the dense covariance (for small meshes)."""
        return self.factor.T @ self.factor


class PhysicsCovariance:
    """A covariance from the physics: ``scale · K_s⁻²`` or ``scale · K_s⁻¹``.

    - ``kind="force"`` (thesis eq 4.5): Λ = K_s⁻², the displacements caused by IID unit-variance
      forces. Its LLSE is the minimum-norm-force field of eq 4.3 (``Physics.reach``).
    - ``kind="energy"``: Λ = K_s⁻¹, the Gaussian whose density is exp(−½ Uᵀ K_s U): the
      strain energy as the negative log-prior. Its LLSE is the field of least strain *energy*
      through the observations, which is what the thesis's prose of §4.1 asks for.

    ``physics`` is a :class:`lipgen.Physics`; columns come from sparse solves
    (``compliance_columns``, and ``solve`` again for K_s⁻²), never from a dense inverse. Anchored
    DOFs have zero variance.
    """

    KINDS = ("force", "energy")

    def __init__(self, physics, scale: float = 1.0, kind: str = "force"):
        if not np.isfinite(scale) or scale <= 0:
            raise ValueError(f"scale must be a positive finite variance, got {scale!r}")
        if kind not in self.KINDS:
            raise ValueError(f"kind must be one of {self.KINDS}, got {kind!r}")
        self.physics = physics
        self.scale = float(scale)
        self.kind = kind
        self.n_dofs = int(physics.mesh.n_dofs)
        free = np.zeros(self.n_dofs, bool)
        free[physics.free_dofs] = True
        self._free = free
        self._solved = None  # unit-scale columns by DOF set, shared with the copies of scaled()

    def scaled(self, scale: float) -> PhysicsCovariance:
        """The same prior with variance ``scale`` instead; it shares its solved columns with this one
        and with its other copies, so a grid of scales (a scale mixture) solves each DOF set once."""
        out = PhysicsCovariance(self.physics, scale, self.kind)
        if self._solved is None:
            self._solved = {}
        out._solved = self._solved
        return out

    def _compliance(self, dofs: np.ndarray) -> np.ndarray:
        """K_s⁻¹[:, dofs] with zero columns for anchored DOFs."""
        out = np.zeros((self.n_dofs, len(dofs)))
        ok = self._free[dofs]
        if ok.any():
            out[:, ok] = self.physics.compliance_columns(dofs[ok])
        return out

    def columns(self, dofs) -> np.ndarray:
        """(3n, d): Λ[:, dofs] (mm²)."""
        dofs = as_index_array(dofs, "dofs", self.n_dofs)
        key = None if self._solved is None else dofs.tobytes()
        C = None if key is None else self._solved.get(key)
        if C is None:
            C = self._compliance(dofs)
            if self.kind == "force":
                C = np.asarray(self.physics.solve(C))
            if key is not None:
                self._solved[key] = C
        return self.scale * C

    def diag_blocks(self, nodes=None, chunk: int = 256) -> np.ndarray:
        """(q, 3, 3) diagonal blocks of Λ, from 3 solves per node (in chunks of ``chunk`` nodes)."""
        nodes = _nodes_arg(nodes, self.n_dofs // 3)
        out = np.empty((len(nodes), 3, 3))
        for s in range(0, len(nodes), chunk):
            part = nodes[s:s + chunk]
            nd = _node_dofs(part)
            C = self._compliance(nd)
            if self.kind == "force":
                C = C.reshape(self.n_dofs, -1, 3)
                out[s:s + chunk] = self.scale * np.einsum("Dqa,Dqb->qab", C, C)
            else:
                q = len(part)
                sub = C[nd].reshape(q, 3, q, 3)
                out[s:s + chunk] = self.scale * sub[np.arange(q), :, np.arange(q), :]
        return out

    def matrix(self) -> np.ndarray:
        """(3n, 3n) dense Λ, from solves (for small meshes and tests)."""
        return self.columns(np.arange(self.n_dofs))


class SumCovariance:
    """The covariance of a sum of independent fields: Λ = Σ parts."""

    def __init__(self, *parts):
        if not parts:
            raise ValueError("SumCovariance needs at least one part")
        sizes = {p.n_dofs for p in parts}
        if len(sizes) != 1:
            raise ValueError(f"all parts must have the same number of DOFs, got {sorted(sizes)}")
        self.parts = parts
        self.n_dofs = sizes.pop()

    def columns(self, dofs) -> np.ndarray:
        """Columns ``dofs`` of the summed covariance, ``(3n, len(dofs))``."""
        return sum(p.columns(dofs) for p in self.parts)

    def diag_blocks(self, nodes=None) -> np.ndarray:
        """Per-node 3x3 diagonal blocks of the summed covariance, ``(n, 3, 3)``."""
        return sum(p.diag_blocks(nodes) for p in self.parts)

    def matrix(self) -> np.ndarray:
        """The summed covariance as a dense ``(3n, 3n)`` matrix."""
        return sum(p.matrix() for p in self.parts)


def _low_rank_split(covariance):
    """(B, rest) for a sum of low-rank factors B and a full-rank remainder, else None."""
    if not isinstance(covariance, SumCovariance):
        return None
    low = [p for p in covariance.parts if isinstance(p, LowRankCovariance)]
    rest = [p for p in covariance.parts if not isinstance(p, LowRankCovariance)]
    if not low or not rest:
        return None
    B = np.vstack([p.factor for p in low])
    return B, (rest[0] if len(rest) == 1 else SumCovariance(*rest))


def _woodbury_gain(B: np.ndarray, rest, dofs: np.ndarray, R: np.ndarray):
    """Gain for Λ = BᵀB + N_full, in the form that stays accurate when N_full is tiny.

    Read y − ȳ = B_oᵀ c + e with c ~ (0, I) and e ~ (0, N), N = N_full[o, o] + R. Then
    ĉ = (I + B_o N⁻¹ B_oᵀ)⁻¹ B_o N⁻¹ (y − ȳ) and x̂ − x̄ = Bᵀ ĉ + N_full[:, o] N⁻¹ (y − ȳ − B_oᵀ ĉ),
    algebraically the same as eq 4.7 (Woodbury) but without inverting the badly conditioned sum.
    """
    other = np.asarray(rest.columns(dofs), dtype=np.float64)  # (3n, d)
    Ninv = pinvh(other[dofs] + np.diag(R))
    Bo = B[:, dofs]
    BN = Bo @ Ninv  # (r, d)
    Mc = np.linalg.solve(np.eye(len(B)) + BN @ Bo.T, BN)  # (r, d): observations -> mode coefficients
    gain = B.T @ Mc + (other @ Ninv) @ (np.eye(len(dofs)) - Bo.T @ Mc)
    cross = B.T @ Bo + other
    return np.ascontiguousarray(gain.T), cross


def _factored_pays(r: int, d: int) -> bool:
    """Whether the factored gain (d x r, then (r + 1) x 3n) beats the dense one (d x 3n): the big
    product shrinks by (r + 1) / d; at 3/4 it no longer pays for the small one."""
    return r + 1 <= 0.75 * d


def _noise_vector(noise, d: int) -> np.ndarray:
    r = np.asarray(noise, dtype=np.float64)
    if r.ndim == 0:
        r = np.full(d, float(r))
    if r.shape != (d,):
        raise ValueError(f"noise must be a scalar or one variance per observed DOF ({d},), got {r.shape}")
    if not np.all(np.isfinite(r)) or (r < 0).any():
        raise ValueError("noise variances must be finite and >= 0 (mm^2)")
    return r


def observed_values(values, d: int) -> np.ndarray:
    """Check observed values: ``(d,)`` or ``(b, d)`` finite floats for ``d`` observed DOFs."""
    Y = np.asarray(values, dtype=np.float64)
    if Y.ndim not in (1, 2) or Y.shape[-1] != d:
        raise ValueError(f"values must have shape ({d},) or (b, {d}) for the {d} observed DOFs, "
                         f"got {Y.shape}")
    if not np.isfinite(Y).all():
        bad = np.argwhere(~np.isfinite(Y))[0]
        raise ValueError(f"values of shape {Y.shape} hold NaN or inf (first at {tuple(bad)}); "
                         "drop those observations from dofs instead")
    return Y


@dataclass(frozen=True, eq=False)
class LLSE:
    """The LLSE for one set of observed DOFs, with its gain precomputed (eq 4.7).

    Build it with :meth:`build` (or :meth:`lipgen.modes.ModeModel.llse`); then
    ``est(values)`` maps observations ``(d,)`` or ``(b, d)`` to fields ``(n, 3)`` or
    ``(b, n, 3)`` with one matrix product.

    Attributes
    ----------
    dofs : (d,) int
        Observed DOFs, indices into the node-major 3n vector.
    gain_t : (d, 3n) float
        The transposed gain (Λ[o, o] + R)⁺ Λ[o, :].
    offset : (3n,) float
        ``mean - gain @ mean[dofs]``, so that the estimate is ``values @ gain_t + offset``.
    mean : (3n,) float
        Prior mean x̄ (mm).
    cross : (3n, d) float
        Λ[:, dofs], kept for the posterior covariance.
    covariance : object
        The prior covariance (see the module docstring).
    noise : (d,) float
        Observation-noise variances (mm²).
    """

    dofs: np.ndarray
    gain_t: np.ndarray
    offset: np.ndarray
    mean: np.ndarray
    cross: np.ndarray
    covariance: object
    noise: np.ndarray
    lowrank: tuple[np.ndarray, np.ndarray] | None = None
    """For a low-rank prior Λ = BᵀB (r, 3n) with r + 1 well below d: ``(coef_t, basis)``, the
    gain in factored form, ``gain_t = coef_t @ B`` with ``coef_t`` (d, r), and ``basis`` (r + 1,
    3n) = B with ``offset`` as its last row. :meth:`estimate` then costs (r + 1) / d of the dense
    product and writes its output once (no pass for the offset)."""

    @classmethod
    def build(cls, covariance, dofs, mean=None, noise=0.0) -> LLSE:
        """Precompute the LLSE of all DOFs from the observed ``dofs``.

        Parameters
        ----------
        covariance : LowRankCovariance, PhysicsCovariance, SumCovariance or alike
            Prior covariance Λ of the 3n displacement vector (mm²).
        dofs : (d,) int
            Observed DOFs, distinct, in ``[0, 3n)``; see :func:`lipgen.dofs`.
        mean : (3n,) float, optional
            Prior mean (mm); zero by default.
        noise : float or (d,) float
            Observation-noise variance (mm²); 0 makes the estimate interpolate where Λ[o, o] is
            full rank.
        """
        D = int(covariance.n_dofs)
        dofs = as_index_array(dofs, "dofs", D, unique=True, allow_empty=False)
        mean = np.zeros(D) if mean is None else as_float_array(mean, "mean", (D,))
        R = _noise_vector(noise, len(dofs))
        split = _low_rank_split(covariance)
        lowrank = None
        if isinstance(covariance, LowRankCovariance) and _factored_pays(covariance.rank_bound, len(dofs)):
            B = covariance.factor
            Bo = B[:, dofs]  # (r, d)
            cross = B.T @ Bo  # (3n, d)
            P = pinvh(Bo.T @ Bo + np.diag(R))
            coef_t = np.ascontiguousarray(P @ Bo.T)  # (d, r)
            gain_t = coef_t @ B
            offset = mean - (mean[dofs] @ coef_t) @ B
            lowrank = (coef_t, np.vstack([B, offset]))
        elif split is None:
            cross = np.asarray(covariance.columns(dofs), dtype=np.float64)
            P = pinvh(cross[dofs] + np.diag(R))
            gain_t = np.ascontiguousarray(P @ cross.T)  # (d, 3n); P symmetric
            offset = mean - mean[dofs] @ gain_t
        else:
            gain_t, cross = _woodbury_gain(*split, dofs, R)
            offset = mean - mean[dofs] @ gain_t
        return cls(dofs=dofs, gain_t=gain_t, offset=offset, mean=mean, cross=cross,
                   covariance=covariance, noise=R, lowrank=lowrank)

    @property
    def n_dofs(self) -> int:
        return self.gain_t.shape[1]

    @property
    def n_nodes(self) -> int:
        return self.gain_t.shape[1] // 3

    def __call__(self, values) -> np.ndarray:
        return self.estimate(values)

    def estimate(self, values) -> np.ndarray:
        """Estimated fields: ``(n, 3)`` for ``values (d,)``, ``(b, n, 3)`` for ``values (b, d)`` (mm)."""
        Y = observed_values(values, len(self.dofs))
        if self.lowrank is not None:
            coef_t, basis = self.lowrank
            r = coef_t.shape[1]
            Z = np.empty((*Y.shape[:-1], r + 1))
            np.matmul(Y, coef_t, out=Z[..., :r])
            Z[..., r] = 1.0  # picks up the offset row of basis
            X = Z @ basis
        else:
            X = Y @ self.gain_t
            X += self.offset
        return X.reshape(*Y.shape[:-1], self.n_nodes, 3)

    def posterior_blocks(self, nodes=None) -> np.ndarray:
        """(q, 3, 3) posterior covariance of each node's displacement (mm²), all nodes by default."""
        nodes = _nodes_arg(nodes, self.n_nodes)
        prior = self.covariance.diag_blocks(nodes)
        G = self.gain_t.T.reshape(self.n_nodes, 3, -1)[nodes]  # (q, 3, d)
        Cx = self.cross.reshape(self.n_nodes, 3, -1)[nodes]
        post = prior - np.einsum("qad,qbd->qab", G, Cx)
        return 0.5 * (post + post.transpose(0, 2, 1))

    def posterior_variance(self) -> np.ndarray:
        """(n, 3) posterior variance of each DOF (mm²)."""
        return np.diagonal(self.posterior_blocks(), axis1=1, axis2=2).copy()

    def posterior_matrix(self) -> np.ndarray:
        """(3n, 3n) full posterior covariance (dense; for small meshes)."""
        post = self.covariance.matrix() - self.gain_t.T @ self.cross.T
        return 0.5 * (post + post.T)


def llse(dofs, values, covariance, mean=None, noise=0.0) -> tuple[np.ndarray, np.ndarray]:
    """One-shot LLSE (eq 4.7): the estimate and each node's posterior covariance.

    Returns
    -------
    estimate : (n, 3) or (b, n, 3) float
        Estimated displacement field(s), mm.
    posterior : (n, 3, 3) float
        Posterior covariance of each node (mm²); the same for every frame of a batch.
    """
    est = LLSE.build(covariance, dofs, mean=mean, noise=noise)
    return est.estimate(values), est.posterior_blocks()
