"""Normalising triangulated marker data into the model frame: thesis §3, or the head pose of least
deformation.

The thesis method (``method="thesis"``), per frame:

1. subtract the nose mark (rigid translation of the head);
2. fit a plane to the outer upper-lip markers and one to the outer lower-lip markers; their
   intersection line is the new x axis (oriented toward the subject's left);
3. y is the global "up" minus its projection onto x, and z = x × y;
4. express the nose-relative points in (x, y, z).

Then ONE similarity transform (rotation, translation and scale, by Umeyama's least squares)
brings the first frame onto the model's marker nodes; the thesis found it with a GUI. It is
applied to every frame, so all the training data live in the model's coordinate system.

Note what step 3 implies: rotations of the head about the vertical axis and about the viewing
axis are removed exactly, but a nod (rotation about x) is not, because y is taken from the
global up. The tests pin this down in closed form. Worse, the lip planes tilt with the lips' own
deformation (jaw opening, one-sided actions), so the frame turns with the expression.

The pose methods (``"least-force"``, ``"least-strain"``, ``"procrustes"``): the nose is the only
head-fixed mark, so it pins the translation; per frame the rotation about it is the one that
leaves the least deformation of the markers from the model's rest markers, measured by the lip
model's own metric (:mod:`lipgen.recon.headpose`): the least force norm of ``Physics.reach`` (eq 4.3),
the least strain energy, or the plain squared distance. One scale comes from the similarity
fitted on the reference frame, as in the thesis. The pipeline uses ``"least-force"``.

Measured (``python -m lipgen.experiments.normalisation 0 1 2 3 4 5``): exact world marks of 6
generated subjects (seeds 0-5, 150 frames, head turning up to 4 deg and moving up to 4 mm, the
one-sided actions on), reference frame ``"auto"`` for every method; normalised markers vs the
true model-frame marks, and the least-strain fields ``Physics.reach`` builds from them vs the
true surface (mm RMS, mean over seeds [worst seed]); head-rotation error (deg RMS over frames,
mean over seeds [largest single frame]). The reach from the TRUE markers is 1.15 mm from the
true surface (the model's floor); the true displacement is 2.74 mm RMS.

=============  ==============  ==============  ====================
method         markers (mm)    fields (mm)     head rotation (deg)
=============  ==============  ==============  ====================
thesis         1.53 [2.00]     1.66 [2.26]     (not a pose)
least-force    0.95 [1.40]     1.36 [1.96]     1.43 [4.72]
least-strain   1.01 [1.17]     1.40 [1.87]     1.63 [4.99]
procrustes     1.11 [1.24]     1.45 [1.87]     1.79 [5.73]
=============  ==============  ==============  ====================

least-force beats the thesis on every seed in both columns and has the lowest mean; least-strain
is better on seeds 2 and 5.

Mis-tracked markers. A quadratic cost lets one bad marker turn the whole frame. So, for the pose
methods, a marker is left out of a frame's pose fit when the pose re-fitted without it costs
less than ``outlier_ratio`` (0.25) times the pose with it (at most 2 per frame; it stays in the
output markers, and the pipeline does not make it a goal of the frame's field). Measured ratios:
the demo's frames with a marker mis-tracked by 5-12 mm give 0.002-0.19; its well-tracked frames
0.29 or more; exact marks with the expressions above 0.42 or more (no marker is left out on any
of the 6 seeds, so the table holds with and without it).

On the demo's triangulated marks (seed 0; the thesis figure with the reference frame 68 chosen
there), markers / fields vs the true surface, mm RMS:

======================================  ===========  ===========
method                                  markers      fields
======================================  ===========  ===========
thesis (before)                         2.55         2.23
least-force, no outlier test            2.04         1.82
least-force (after, the default)        1.07         1.13
least-strain / procrustes               1.25 / 1.38  1.26 / 1.36
======================================  ===========  ===========

(on the exact marks with that reference frame: thesis 2.47 mm, least-force 0.83 mm).

What it confuses with head motion (``lipgen.experiments.normalisation.action_bias_deg``): the
rotation read into a single action at activation 1 with the head still, force metric, deg (nod x,
turn y, roll z): jaw_open -2.6 nod; lip_corner_puller -2.4 nod; lip_corner_depressor +1.8 nod;
lip_corner_puller_left (-1.1, -1.2, -3.2), 3.6 in all, the worst; lip_corner_depressor_left
(0.9, 1.1, 1.8); upper_lip_raiser_left 0.7; jaw_shift_left 1.0 (right: mirrored). The energy
and Euclidean metrics confuse the one-sided corner puller more (4.4 and 4.7 deg) and the jaw less
(0.8, 0.7 deg). A robust (Tukey IRLS) Procrustes about the nose was also tried in a prototype:
markers 1.00 mm on seeds 0-4 (least-force 0.87 mm there), so it was not kept.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np

from lipgen._validate import as_float_array, as_index_array
from lipgen.recon.headpose import pose_normalize
from lipgen.recon.similarity import Normalization, Similarity, most_neutral_frame, umeyama

__all__ = [
    "Similarity", "umeyama", "fit_plane", "lip_frame", "lip_subsets", "Normalization",
    "normalize_markers", "METHODS",
]

METHODS = ("thesis", "least-force", "least-strain", "procrustes")
"""Normalisation methods: the thesis's lip-plane frame, or the head rotation about the nose that
leaves the least force (eq 4.3 metric), the least strain energy, or the least squared marker
displacement (a Procrustes fit about the nose); see the module docstring."""

log = logging.getLogger(__name__)


def fit_plane(points) -> tuple[np.ndarray, np.ndarray, float]:
    """Total-least-squares plane through ``points (k, 3)``, k >= 3.

    Returns
    -------
    centroid : (3,) float
    normal : (3,) float
        Unit normal (sign arbitrary).
    flatness : float
        Smallest over middle singular value: 0 for coplanar points, near 1 for no plane at all.
    """
    P = as_float_array(points, "points", (None, 3))
    if len(P) < 3:
        raise ValueError(f"a plane needs at least 3 points, got {len(P)}")
    c = P.mean(0)
    _, S, Vt = np.linalg.svd(P - c)
    if S[1] <= 1e-12 * max(S[0], 1e-300):
        raise ValueError("the points are collinear; no plane is defined")
    return c, Vt[2], float(S[2] / S[1])


def lip_frame(upper_points, lower_points, up=(0.0, 1.0, 0.0), x_hint=(1.0, 0.0, 0.0)
              ) -> tuple[np.ndarray, float]:
    """The thesis's lip coordinate frame from upper- and lower-lip points.

    Parameters
    ----------
    upper_points, lower_points : (k, 3) float
        Outer upper- and lower-lip markers (k >= 3 each, not collinear).
    up : (3,) float
        The global y direction of the data's frame.
    x_hint : (3,) float
        A direction on the subject's-left side, used only to choose the sign of x.

    Returns
    -------
    R : (3, 3) float
        Rows are the unit axes x, y, z (right-handed), so ``R @ p`` expresses ``p`` in the frame.
    angle : float
        Angle between the two planes, radians; near 0 the x axis is ill-defined.
    """
    _, n_up, _ = fit_plane(upper_points)
    _, n_lo, _ = fit_plane(lower_points)
    x = np.cross(n_up, n_lo)
    sin = float(np.linalg.norm(x))
    if sin < 1e-9:
        raise ValueError("the upper- and lower-lip planes are parallel; their intersection (x axis) "
                         "is undefined")
    x /= sin
    if x @ np.asarray(x_hint, float) < 0:
        x = -x
    g = np.asarray(up, dtype=np.float64)
    y = g - (g @ x) * x
    ny = np.linalg.norm(y)
    if ny < 1e-9:
        raise ValueError("the lip-plane intersection is parallel to the global up axis; y is undefined")
    y /= ny
    return np.stack([x, y, np.cross(x, y)]), float(np.arcsin(min(sin, 1.0)))


def lip_subsets(marker_names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the outer upper-lip and lower-lip markers, chosen by name.

    Upper: names starting with ``upper`` or ``bow``; lower: names starting with ``lower``. The
    corner markers belong to neither lip.

    Raises
    ------
    ValueError
        When either subset has fewer than 3 markers (pass explicit indices instead).
    """
    names = [str(n) for n in marker_names]
    upper = np.array([i for i, n in enumerate(names) if n.startswith(("upper", "bow"))], dtype=np.int64)
    lower = np.array([i for i, n in enumerate(names) if n.startswith("lower")], dtype=np.int64)
    if len(upper) < 3 or len(lower) < 3:
        raise ValueError(
            f"cannot choose the lip-plane markers by name from {names}: found {len(upper)} upper "
            f"('upper*', 'bow*') and {len(lower)} lower ('lower*'), need 3 each; pass the index "
            "lists upper= and lower= explicitly")
    return upper, lower


def normalize_markers(markers, nose, upper, lower, model_markers, model_nose=None, visible=None,
                      up=(0.0, 1.0, 0.0), x_hint=(1.0, 0.0, 0.0), reference_frame: int | str = 0,
                      method: str = "thesis", physics=None, outlier_ratio: float = 0.25,
                      max_outliers: int = 2, reference_candidates=None,
                      reference: Similarity | None = None) -> Normalization:
    """Bring triangulated markers into the model frame (thesis §3, or a least-deformation pose).

    Parameters
    ----------
    markers : (F, P, 3) float
        Triangulated markers in the data's frame (NaN allowed where not visible).
    nose : (F, 3) float
        The nose mark in each frame.
    upper, lower : (a,) int, (b,) int
        Marker indices of the outer upper- and lower-lip subsets (see :func:`lip_subsets`).
    model_markers : (P, 3) float
        The model's marker nodes at rest, model frame (mm).
    model_nose : (3,) float, optional
        The model's nose point; when given it joins the similarity fit (the data's nose is the
        origin after step 1).
    visible : (F, P) bool, optional
        Which markers were seen; defaults to the finite ones.
    up, x_hint : (3,) float
        Global up and a subject's-left direction in the data's frame (see :func:`lip_frame`).
    reference_frame : int or "auto"
        The frame the similarity is fitted on. The thesis used the first frame, which assumes
        the subject starts at rest. ``"auto"`` takes the frame whose lip-frame markers a
        similarity brings closest to the model's rest markers (the most neutral-looking frame,
        among those that see the most markers).
    reference_candidates : (k,) int, optional
        The frames ``"auto"`` may choose from (default all): the training frames, so that no
        held-out test frame shapes the normalisation.
    reference : Similarity, optional
        The reference of another normalisation of the same subject on the same rig (its
        ``Normalization.similarity``, e.g. the training recording's), so that these frames are
        expressed in that recording's frame of reference instead of one fitted on a frame of
        their own; ``reference_frame`` and ``reference_candidates`` are then not used, and the
        result's ``reference_frame`` is -1. ``"thesis"`` applies it as the one similarity; the
        pose methods take its scale and start each frame's rotation from its rotation. A
        recording's own ``similarity`` passed back gives its own result (see
        :func:`lipgen.recon.headpose.pose_normalize`). A different subject has a different rest
        shape and size, so it needs a reference of its own.
    method : str
        One of :data:`METHODS`. ``"thesis"`` (the default here) is steps 1-4 of the module
        docstring; the others rotate each frame about the nose (see :mod:`lipgen.recon.headpose`) and
        need ``model_nose``; ``"least-force"`` and ``"least-strain"`` also need ``physics``.
    physics : lipgen.fem.Physics, optional
        The lip model whose marker nodes ``model_markers`` are (its metric weighs the residual).
    outlier_ratio, max_outliers : float, int
        Pose methods only: a marker is left out of a frame's pose fit (up to ``max_outliers`` per
        frame, one at a time) when the pose re-fitted without it costs less than
        ``outlier_ratio`` times the pose with it, i.e. one marker carried most of the frame's
        deformation cost. ``outlier_ratio=0`` turns this off. See the module docstring.

    Returns
    -------
    Normalization
    """
    if method not in METHODS:
        raise ValueError(f"unknown normalisation method {method!r}; choose one of {METHODS}")
    X = as_float_array(markers, "markers", (None, None, 3), finite=False)
    F, P, _ = X.shape
    N = as_float_array(nose, "nose", (F, 3))
    M = as_float_array(model_markers, "model_markers", (P, 3))
    up_i = as_index_array(upper, "upper", P, unique=True)
    lo_i = as_index_array(lower, "lower", P, unique=True)
    vis = np.all(np.isfinite(X), axis=2) if visible is None else np.asarray(visible, dtype=bool)
    if vis.shape != (F, P):
        raise ValueError(f"visible must have shape ({F}, {P}), got {vis.shape}")
    vis = vis & np.all(np.isfinite(X), axis=2)
    if reference is not None and not isinstance(reference, Similarity):
        raise TypeError(f"reference must be a Similarity (a Normalization's .similarity), got "
                        f"{type(reference).__name__}")
    if reference is not None and not (np.isfinite(reference.scale) and reference.scale > 0):
        raise ValueError(f"reference.scale must be finite and > 0, got {reference.scale}")
    if reference is None and reference_frame != "auto" and not (isinstance(reference_frame, int | np.integer)
                                          and 0 <= reference_frame < F):
        raise ValueError(f"reference_frame must be 'auto' or a frame in [0, {F}), got {reference_frame!r}")
    rel = X - N[:, None, :]
    if method != "thesis":
        if not 0 <= outlier_ratio < 1 or int(max_outliers) < 0:
            raise ValueError(f"outlier_ratio must be in [0, 1) and max_outliers >= 0, got {outlier_ratio} "
                             f"and {max_outliers}")
        return pose_normalize(rel, vis, M, model_nose, reference_frame, method, physics,
                              float(outlier_ratio), int(max_outliers), reference_candidates, reference)
    rotations = np.full((F, 3, 3), np.nan)
    angle = np.full(F, np.nan)
    for f in range(F):
        u, lo = up_i[vis[f, up_i]], lo_i[vis[f, lo_i]]
        if len(u) >= 3 and len(lo) >= 3:
            try:
                rotations[f], angle[f] = lip_frame(rel[f, u], rel[f, lo], up, x_hint)
            except ValueError as exc:
                log.warning("frame %d: no lip frame (%s)", f, exc)
    good = np.flatnonzero(np.isfinite(angle))
    if len(good) == 0:
        raise ValueError("no frame has 3 visible, non-collinear markers on each lip; cannot normalise")
    borrowed = ~np.isfinite(angle)
    if borrowed.any():
        nearest = good[np.abs(good[None, :] - np.arange(F)[:, None]).argmin(1)]
        rotations[borrowed] = rotations[nearest[borrowed]]
        log.warning("%d frame(s) borrowed the lip frame of a neighbour (too few visible markers)",
                    int(borrowed.sum()))
    local = np.einsum("fij,fpj->fpi", rotations, rel)
    if reference is not None:
        out = reference.apply(local)
        out[~vis] = np.nan
        return Normalization(out, rotations, reference, angle, borrowed, float("nan"), -1)
    if reference_frame == "auto":
        reference_frame = most_neutral_frame(local, vis, M, model_nose, reference_candidates)
        log.info("normalisation: frame %d looks the most neutral; the similarity is fitted there",
                 reference_frame)
    seen = vis[reference_frame]
    src, dst = local[reference_frame, seen], M[seen]
    if model_nose is not None:
        src = np.vstack([src, np.zeros(3)])
        dst = np.vstack([dst, as_float_array(model_nose, "model_nose", (3,))])
    if len(src) < 3:
        raise ValueError(f"reference frame {reference_frame} has only {int(seen.sum())} visible "
                         "markers; the similarity to the model needs 3")
    sim = umeyama(src, dst)
    fit_rms = float(np.sqrt(((sim.apply(src) - dst) ** 2).sum(1).mean()))
    out = sim.apply(local)
    out[~vis] = np.nan
    return Normalization(out, rotations, sim, angle, borrowed, fit_rms, int(reference_frame))
