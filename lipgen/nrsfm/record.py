"""The result record of NRSfM and the method table (what :func:`lipgen.nrsfm.reconstruct` accepts)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lipgen.nrsfm._tracks import check_k

__all__ = ["Reconstruction", "METHODS", "DEFAULT_METHOD", "MEAN_PLUS_MODES", "n_basis_shapes",
           "check_method_k"]

METHODS: dict[str, str] = {
    "bregler": "Bregler, Hertzmann & Biermann 1999 as written: rank-3K SVD, per-frame rank-1 "
               "pose/weights, one 3x3 metric upgrade",
    "dai": "Dai, Li & He 2012 (prior-free): rotations from the orthonormality of one corrective "
           "triple (deterministic Levenberg-Marquardt), then the shapes of least trace norm that "
           "reproject exactly (block matrix method, as published); when the tracks are exactly of rank "
           "<= 3K (noise-free K shapes) exactly K basis shapes fitted with the rotations fixed instead",
    "dai-ba": "'dai', then K basis shapes fitted with the rotations fixed and low-rank bundle adjustment "
              "(Levenberg-Marquardt on the reprojection error), kept only if it lowers that error and its "
              "depth is neither deeper nor rougher than 1.5 times dai's and stays plausible against the "
              "trace-norm shapes (lipgen.nrsfm.keep); else exactly 'dai'",
    "em-ppca": "Torresani, Hertzmann & Bregler 2008 (EM-Gaussian): mean shape plus K Gaussian "
               "deformation modes, fitted by EM from a rigid start; here K counts the modes, so the "
               "model has K + 1 basis shapes (rank 3(K + 1))",
    "em-pnd": "Lee, Cho & Oh 2013/2017 (EM-PND): aligned shapes normally distributed about a mean, "
              "deformations held to the Procrustean constraints (no translation, no rotation about the "
              "mean), fitted by EM from 'dai' at K + 1 basis shapes and kept only if its depth stays "
              "plausible; K counts the modes (K + 1 basis shapes); k='auto' by the BIC",
}
"""Method names accepted by :func:`reconstruct`, with what each does."""

DEFAULT_METHOD = "dai"
"""The method :func:`reconstruct` uses unless told."""

MEAN_PLUS_MODES = frozenset({"em-ppca", "em-pnd"})
"""Methods whose ``k`` counts deformation modes beyond a mean shape (``k + 1`` basis shapes)."""


def n_basis_shapes(k: int, method: str) -> int:
    """Number of basis shapes of ``method`` run with ``k``: ``k + 1`` for em-ppca, else ``k``."""
    return k + 1 if method in MEAN_PLUS_MODES else k


def check_method_k(k, method: str, n_frames: int, n_points: int, n_observed: int) -> int:
    """:func:`check_k` for ``method``'s meaning of k (em-ppca: k >= 0 modes, k + 1 basis shapes)."""
    if method not in MEAN_PLUS_MODES:
        return check_k(k, n_frames, n_points, n_observed, unknowns_per_frame=5)
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)):
        raise TypeError(f"k (number of deformation modes) must be an integer, got {k!r}")
    if k < 0:
        raise ValueError(f"k (number of deformation modes of {method!r}) must be at least 0, got {k}")
    k = int(k)
    limit = min(2 * n_frames, n_points - 1) // 3 - 1
    if k > limit:
        raise ValueError(
            f"k={k} is too large for method {method!r} on tracks of {n_frames} frames and {n_points} "
            f"points: k deformation modes + the mean = {k + 1} basis shapes, whose rank-3(k + 1) model "
            f"needs 3(k + 1) <= min(2F, P - 1) = {min(2 * n_frames, n_points - 1)}, so k <= {limit}")
    try:
        check_k(k + 1, n_frames, n_points, n_observed, unknowns_per_frame=5)
    except ValueError as exc:
        raise ValueError(f"method {method!r} with k={k} deformation modes ({k + 1} basis shapes): "
                         f"{exc}") from None
    return int(k)


@dataclass(frozen=True)
class Reconstruction:
    """A non-rigid reconstruction under orthography (arrays are read-only).

    Attributes
    ----------
    rotations : (F, 3, 3) float
        Object-to-camera rotations; the third row is the cross product of the first two.
    weights : (F, N) float
        Configuration weights (they carry each frame's projection scale). N = K basis shapes,
        except for ``method="em-ppca"`` where N = K + 1 (mean shape first, then the K modes), and
        for ``"dai"`` (or a rejected ``"dai-ba"``) on tracks not exactly of rank <= 3K, where the
        trace-norm shapes are returned whole: N is their numerical rank (``info["shapes"]``).
    basis : (N, 3, P) float
        Basis shapes in the object frame.
    translation : (F, 2) float
        Image translation of each frame: ``W_f ~ (R_f S_f)[:2] + t_f``.
    method : str
    k : int
        The K passed to :func:`reconstruct` (for em-ppca the number of modes beyond the mean).
    reprojection_rms : float
        RMS over observed coordinates of the reprojection residual, in the units of W.
    info : dict
        Diagnostics of the method (costs, iteration counts).
    """

    rotations: np.ndarray
    weights: np.ndarray
    basis: np.ndarray
    translation: np.ndarray
    method: str
    k: int
    reprojection_rms: float
    info: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        for name in ("rotations", "weights", "basis", "translation"):
            arr = np.array(getattr(self, name), dtype=np.float64)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def depth_supported(self) -> bool:
        """False when the depth was dropped because the tracks do not determine the rotations
        (``info["depth_support"]``, :func:`lipgen.nrsfm.support.depth_support`; ``dai`` with
        ``k="auto"``): the shapes are then the flat answer (zero depth). True otherwise, also when
        no test was made."""
        return bool(self.info.get("depth_support", {}).get("supported", True))

    @property
    def n_frames(self) -> int:
        return self.rotations.shape[0]

    @property
    def n_points(self) -> int:
        return self.basis.shape[2]

    @property
    def object_shapes(self) -> np.ndarray:
        """(F, 3, P) shapes in the object frame, ``sum_k weights[f, k] basis[k]``."""
        return np.einsum("fk,kip->fip", self.weights, self.basis)

    @property
    def shapes(self) -> np.ndarray:
        """(F, 3, P) shapes in the camera frame (x right, y down as the tracks, z depth), centred."""
        # einsum, not BLAS: the same bytes whatever the caller's BLAS thread count
        return np.einsum("fij,fjp->fip", self.rotations, self.object_shapes)

    @property
    def S(self) -> np.ndarray:
        """(3F, P) camera-frame shapes, rows x1, y1, z1, x2, ... (the benchmark layout)."""
        return self.shapes.reshape(-1, self.n_points)

    def reproject(self) -> np.ndarray:
        """(2F, P) predicted tracks, rows u1, v1, u2, ..."""
        return (self.shapes[:, :2] + self.translation[:, :, None]).reshape(-1, self.n_points)
