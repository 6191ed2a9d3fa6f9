"""Learned modes of lip motion: snapshot PCA (thesis Appendix B), synthesis and LLSE (eq 4.7).

:class:`ModeModel` learns the mean displacement and the principal modes of a set of displacement
fields. The sample covariance is the unbiased ``AᵀA / (F − 1)`` of the centred frames ``A``
(F, 3n); its eigenvectors are found from the small F×F matrix ``A Aᵀ`` and mapped back through
``Aᵀ`` (the snapshot method), or, when there are more frames than DOFs, from the 3n×3n matrix
directly; both give the same modes. The model keeps the first ``n_modes`` and, for the thesis's
"full sample covariance" estimate, the whole non-zero spectrum (at most F − 1 modes).
"""

from __future__ import annotations

import json
import logging
import os

import numpy as np

from lipgen._io import load_npz, save_npz
from lipgen._validate import as_float_array, check_finite
from lipgen.errors import ModelFileError, TopologyMismatchError
from lipgen.modes.llse import LLSE, LowRankCovariance

__all__ = ["ModeModel", "as_frames"]

log = logging.getLogger(__name__)

_KIND, _SCHEMA = "lipgen.ModeModel", 1


def as_frames(U, name: str = "U_frames") -> np.ndarray:
    """(F, 3n) float view of displacement frames given as ``(F, n, 3)`` or ``(F, 3n)``."""
    X = np.asarray(U, dtype=np.float64)
    if X.ndim == 3 and X.shape[2] == 3:
        X = X.reshape(len(X), -1)
    elif X.ndim != 2 or X.shape[1] % 3:
        raise ValueError(f"{name} must have shape (F, n, 3) or (F, 3n), got {X.shape}")
    check_finite(X, name)
    return X


def _flip_signs(S: np.ndarray) -> np.ndarray:
    """Make the largest-magnitude entry of every row positive (as sklearn's svd_flip)."""
    if S.size == 0:
        return S
    idx = np.argmax(np.abs(S), axis=1)
    signs = np.sign(S[np.arange(len(S)), idx])
    signs[signs == 0] = 1.0
    return S * signs[:, None]


def _spectrum(A: np.ndarray, method: str) -> tuple[np.ndarray, np.ndarray]:
    """Non-zero eigenpairs of ``AᵀA`` (descending): eigenvalues (r,), orthonormal rows (r, D)."""
    F, D = A.shape
    if method == "auto":
        method = "snapshot" if F <= D else "covariance"
    if method == "snapshot":
        w, V = np.linalg.eigh(A @ A.T)  # Appendix B: eigenvectors of the small F x F matrix ...
    elif method == "covariance":
        w, V = np.linalg.eigh(A.T @ A)
    else:
        raise ValueError(f"method must be 'auto', 'snapshot' or 'covariance', got {method!r}")
    w, V = w[::-1], V[:, ::-1]
    top = max(float(w[0]), 0.0) if len(w) else 0.0
    keep = (w > max(F, D) * np.finfo(float).eps * top) & (w > 0)  # at most F - 1 survive centring
    w, V = w[keep], V[:, keep]
    # ... mapped back through A^T (eq B.3) and scaled to unit length: |A^T v|^2 = v^T A A^T v = w.
    S = (A.T @ V / np.sqrt(w)).T if method == "snapshot" else V.T
    return w, _flip_signs(np.ascontiguousarray(S))


class ModeModel:
    """Learned displacement modes (thesis §4.2, Appendix B).

    Parameters
    ----------
    n_modes : int
        Number of modes kept (the thesis keeps 10).
    method : {"auto", "snapshot", "covariance"}
        ``"snapshot"`` diagonalises the F×F matrix (Appendix B); ``"covariance"`` the 3n×3n one;
        ``"auto"`` takes the smaller. The results agree to rounding.

    Attributes
    ----------
    mean_ : (3n,) float
        Mean displacement (mm), node-major.
    components_ : (k, 3n) float
        Orthonormal modes, largest variance first; the largest-magnitude entry of each is positive.
    explained_variance_ : (k,) float
        Variance along each mode (mm²), unbiased (1 / (F − 1)).
    explained_variance_ratio_ : (k,) float
        Share of the total variance (the trace of the sample covariance).
    total_variance_ : float
        Trace of the sample covariance (mm²).
    full_components_ : (r, 3n) float, full_variance_ : (r,) float
        The whole non-zero spectrum of the sample covariance, r ≤ F − 1.
    n_nodes_ : int
    n_frames_ : int
    topology_id_ : str
        The mesh's topology id if one was given to :meth:`fit`, else "".
    provenance_ : dict or None
        What the model was trained on, set by ``lipgen train`` and kept by :meth:`save`:
        ``{"dataset": path, "dataset_id": manifest digest, "frames": [frame indices], ...}``;
        ``lipgen evaluate`` refuses to test on those frames of that dataset. None if unknown.
    """

    provenance_: dict | None = None
    marker_coverage_: np.ndarray | None = None
    """(P,) share of the training frames that measured each marker (set by :meth:`fit_measured`;
    None when unknown). A marker at 0 was never measured: the learned estimators ignore it."""

    def __init__(self, n_modes: int = 10, method: str = "auto"):
        if isinstance(n_modes, bool) or not isinstance(n_modes, int | np.integer) or n_modes < 1:
            raise ValueError(f"n_modes must be a positive integer, got {n_modes!r}")
        if method not in ("auto", "snapshot", "covariance"):
            raise ValueError(f"method must be 'auto', 'snapshot' or 'covariance', got {method!r}")
        self.n_modes = int(n_modes)
        self.method = method

    # ---- fitting ------------------------------------------------------------------------
    def fit(self, U_frames, mesh=None) -> ModeModel:
        """Learn the mean and modes of ``U_frames`` ((F, n, 3) or (F, 3n), mm).

        ``mesh`` (a :class:`lipgen.LipMesh`), if given, records its topology id and is checked
        against the frames' node count.
        """
        X = as_frames(U_frames)
        F, D = X.shape
        if F < self.n_modes + 1:
            raise ValueError(
                f"{F} frame(s) cannot give {self.n_modes} modes: F frames span at most F - 1 "
                f"directions about their mean. Give at least {self.n_modes + 1} frames or lower n_modes."
            )
        if mesh is not None and mesh.n_nodes != D // 3:
            raise TopologyMismatchError(
                f"frames have {D // 3} nodes but mesh {mesh.name!r} has {mesh.n_nodes}")
        mean = X.mean(axis=0)
        A = X - mean
        w, S = _spectrum(A, self.method)
        var = w / (F - 1)
        total = float(np.einsum("ij,ij->", A, A)) / (F - 1)
        if len(var) < self.n_modes:
            log.warning("the frames span only %d independent directions; keeping %d of the %d modes asked",
                        len(var), len(var), self.n_modes)
        return self._set_fitted(mean, S, var, total, D // 3, F, "" if mesh is None else str(mesh.topology_id))

    def _set_fitted(self, mean, S, var, total, n_nodes, n_frames, topology_id) -> ModeModel:
        """Store the fitted attributes: mean (3n,), all components S (r, 3n) and variances (r,)."""
        k = min(self.n_modes, len(var))
        self.mean_ = mean
        self.full_components_, self.full_variance_ = S, var
        self.components_, self.explained_variance_ = S[:k], var[:k]
        self.total_variance_ = total
        self.explained_variance_ratio_ = var[:k] / total if total > 0 else np.zeros(k)
        self.n_nodes_, self.n_frames_ = n_nodes, n_frames
        self.topology_id_ = topology_id
        return self

    def fit_measured(self, fields, measured, physics) -> ModeModel:
        """Learn from least-strain fields knowing which markers each frame measured.

        The mean and covariance of the marker DOFs are the EM estimates from the measured entries
        only, mapped to the fields through the reach map (:func:`lipgen.modes.missing.measured_field_model`);
        a marker's interpolated value in a frame that did not measure it is not learned from. With
        every marker measured in every frame this equals :meth:`fit` on ``fields``.

        Parameters
        ----------
        fields : (F, n, 3) float
            Least-strain fields (``Physics.reach`` of each frame's measured markers), mm.
        measured : (F, P) bool
            Which of the mesh's P markers were goals of each frame's field.
        physics : lipgen.Physics
            The reconstruction model (its mesh's markers).
        """
        from lipgen.modes.missing import measured_field_model

        F = len(fields)
        if F < self.n_modes + 1:
            raise ValueError(f"{F} frame(s) cannot give {self.n_modes} modes; give at least "
                             f"{self.n_modes + 1} frames or lower n_modes")
        out = measured_field_model(fields, measured, physics)
        _, s, Vt = np.linalg.svd(out["factor"], full_matrices=False)
        var = s**2
        keep = var > max(F, var.size) * np.finfo(float).eps * (var[0] if var.size else 0.0)
        var, S = var[keep], _flip_signs(np.ascontiguousarray(Vt[keep]))
        self._set_fitted(out["mean"], S, var, float(var.sum()), physics.mesh.n_nodes, F,
                         str(physics.mesh.topology_id))
        self.marker_coverage_ = out["coverage"]
        return self

    def fit_from_markers(self, physics, goals, markers=None) -> ModeModel:
        """Train from marker data as the thesis did (§4.1–4.2).

        Each frame's full displacement field is the least-strain field reaching the marker goals
        (``physics.reach``, eq 4.3); the modes are learned from those fields.

        Parameters
        ----------
        physics : lipgen.Physics
            The reconstruction model.
        goals : (F, k, 3) float
            Marker displacement goals (mm, model frame), one row per marker.
        markers : (k,) int, optional
            Node of each marker; the mesh's markers by default.
        """
        from lipgen.fem import dofs as node_dofs

        mesh = physics.mesh
        nodes = mesh.markers if markers is None else np.asarray(markers)
        G = as_float_array(goals, "goals", (None, len(nodes), 3))
        U, _ = physics.reach(node_dofs(nodes), G.reshape(len(G), -1))
        return self.fit(U, mesh=mesh)

    # ---- using the model ----------------------------------------------------------------
    def _check_fitted(self) -> None:
        if not hasattr(self, "components_"):
            raise RuntimeError("this ModeModel is not fitted yet; call fit() or ModeModel.load()")

    @property
    def n_components_(self) -> int:
        self._check_fitted()
        return len(self.components_)

    def synthesize(self, coef) -> np.ndarray:
        """Fields ``mean + coef @ components``: ``(n, 3)`` for ``(j,)``, ``(F, n, 3)`` for ``(F, j)``.

        ``j`` may be fewer than the number of modes (the first ``j`` are used).
        """
        self._check_fitted()
        c = as_float_array(coef, "coef")
        if c.ndim not in (1, 2) or c.shape[-1] > len(self.components_):
            raise ValueError(f"coef must have shape (j,) or (F, j) with j <= {len(self.components_)}, "
                             f"got {c.shape}")
        X = self.mean_ + c @ self.components_[: c.shape[-1]]
        return X.reshape(*c.shape[:-1], self.n_nodes_, 3)

    def project(self, U) -> np.ndarray:
        """Mode coefficients: ``(n, 3)``/``(3n,)`` -> ``(k,)``; ``(F, n, 3)``/``(F, 3n)`` -> ``(F, k)``."""
        self._check_fitted()
        X = np.asarray(U, dtype=np.float64)
        D = 3 * self.n_nodes_
        single = X.shape in ((D,), (self.n_nodes_, 3))
        X = as_frames(X.reshape(1, D) if single else X, "U")
        if X.shape[1] != D:
            raise TopologyMismatchError(
                f"fields have {X.shape[1] // 3} nodes; this model has {self.n_nodes_}")
        c = (X - self.mean_) @ self.components_.T
        return c[0] if single else c

    def check_mesh(self, mesh) -> None:
        """Raise :class:`TopologyMismatchError` unless ``mesh`` is the mesh this model was fitted on."""
        self._check_fitted()
        if mesh.n_nodes != self.n_nodes_:
            raise TopologyMismatchError(
                f"this ModeModel has {self.n_nodes_} nodes but mesh {mesh.name!r} has {mesh.n_nodes}; "
                "fit a model on this mesh")
        if self.topology_id_ and mesh.topology_id != self.topology_id_:
            raise TopologyMismatchError(
                f"mesh {mesh.name!r} (topology {mesh.topology_id}) is not the mesh this model was fitted on "
                f"(topology {self.topology_id_}); the node counts agree but the faces differ")

    def covariance(self, n_modes: int | str | None = None) -> LowRankCovariance:
        """The learned prior covariance (mm²).

        ``None`` uses the kept modes ``S Λ Sᵀ`` (as the thesis reassembles it), an int the first
        that many, ``"full"`` the whole sample covariance.
        """
        self._check_fitted()
        if isinstance(n_modes, str):
            if n_modes != "full":
                raise ValueError(f"n_modes must be an int, None or 'full', got {n_modes!r}")
            S, var = self.full_components_, self.full_variance_
        else:
            k = len(self.components_) if n_modes is None else int(n_modes)
            if not 0 <= k <= len(self.full_components_):
                raise ValueError(f"n_modes must be in [0, {len(self.full_components_)}], got {n_modes}")
            S, var = self.full_components_[:k], self.full_variance_[:k]
        return LowRankCovariance(np.sqrt(var)[:, None] * S)

    def llse(self, dofs, n_modes: int | str | None = None, noise=0.0) -> LLSE:
        """The precomputed LLSE (eq 4.7) of all DOFs from ``dofs``, with this model as the prior."""
        return LLSE.build(self.covariance(n_modes), dofs, mean=self.mean_, noise=noise)

    # ---- files --------------------------------------------------------------------------
    def save(self, path: str | os.PathLike) -> None:
        """Write the fitted model to ``path`` (.npz, atomic, schema-versioned)."""
        self._check_fitted()
        save_npz(path, _KIND, _SCHEMA, {
            "mean": self.mean_, "full_components": self.full_components_,
            "full_variance": self.full_variance_, "total_variance": np.float64(self.total_variance_),
            "n_modes": np.int64(self.n_modes), "n_kept": np.int64(len(self.components_)),
            "n_frames": np.int64(self.n_frames_), "topology_id": np.array(self.topology_id_),
            "method": np.array(self.method),
            **({} if self.provenance_ is None else {"provenance": np.array(json.dumps(self.provenance_))}),
            **({} if self.marker_coverage_ is None
               else {"marker_coverage": np.asarray(self.marker_coverage_)}),
        })

    @classmethod
    def load(cls, path: str | os.PathLike) -> ModeModel:
        """Read a model written by :meth:`save`; raises :class:`ModelFileError` if it is not valid."""
        keys = ("mean", "full_components", "full_variance", "total_variance", "n_modes", "n_kept",
                "n_frames", "topology_id", "method")
        d = load_npz(path, _KIND, _SCHEMA, required=keys)
        try:
            mean = np.asarray(d["mean"], np.float64)
            S = np.asarray(d["full_components"], np.float64)
            var = np.asarray(d["full_variance"], np.float64)
            k, n_modes = int(d["n_kept"]), int(d["n_modes"])
            ok = (mean.ndim == 1 and mean.size % 3 == 0 and S.ndim == 2 and S.shape[1] == mean.size
                  and var.shape == (len(S),) and 0 <= k <= len(S) and np.isfinite(S).all()
                  and np.isfinite(mean).all() and (var >= 0).all())
            model = cls(n_modes=n_modes, method=str(d["method"]))
        except (TypeError, ValueError) as exc:
            raise ModelFileError(f"{path} holds an inconsistent ModeModel: {exc}") from exc
        if not ok:
            raise ModelFileError(f"{path} holds an inconsistent ModeModel (mean {mean.shape}, "
                                 f"components {S.shape}, variances {var.shape}, kept {k})")
        total = float(d["total_variance"])
        _check_loaded(path, S, var, total)
        model.mean_, model.full_components_, model.full_variance_ = mean, S, var
        model.components_, model.explained_variance_ = S[:k], var[:k]
        model.total_variance_ = total
        model.explained_variance_ratio_ = var[:k] / total if total > 0 else np.zeros(k)
        model.n_nodes_, model.n_frames_ = mean.size // 3, int(d["n_frames"])
        model.topology_id_ = str(d["topology_id"])
        if "marker_coverage" in d:
            model.marker_coverage_ = np.asarray(d["marker_coverage"], np.float64)
        if "provenance" in d:  # (files written before provenance have none)
            try:
                model.provenance_ = json.loads(str(d["provenance"]))
            except ValueError as exc:
                raise ModelFileError(f"{path} holds an unreadable provenance record: {exc}") from exc
        return model


def _check_loaded(path, S: np.ndarray, var: np.ndarray, total: float) -> None:
    """Refuse a model file whose numbers contradict each other: components that are not
    orthonormal rows, or a total variance that is not a finite number at least the sum of the
    mode variances (:meth:`ModeModel.fit` writes both so)."""
    if len(S):
        # A mode of tiny variance is only as orthonormal as the snapshot method can make it (its
        # error grows like eps * top / variance), so each pair's error is weighed by its share.
        share = np.sqrt(np.clip(var / var.max(), 0.0, 1.0)) if len(var) == len(S) and var.max() > 0 else 1.0
        err = float((np.abs(S @ S.T - np.eye(len(S))) * np.outer(share, share)).max())
        if not err <= 1e-6:  # also catches NaN
            raise ModelFileError(f"{path}: the components are not orthonormal (|S Sᵀ - I| up to {err:.3g}); "
                                 "the file was altered or is not a lipgen model. Re-train it")
    if not np.isfinite(total) or total < 0 or total < var.sum() * (1 - 1e-9) - 1e-12:
        raise ModelFileError(f"{path}: total_variance {total!r} is not a finite number at least the sum of "
                             f"the mode variances ({var.sum():.6g}); the file is inconsistent. Re-train it")
