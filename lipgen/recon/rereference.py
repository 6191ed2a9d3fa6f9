"""A reconstruction expressed in another recording's frame of reference (same subject, same rig).

:func:`lipgen.recon.pipeline.reconstruct_dataset` normalises each recording on its own reference:
the scale (and, for the thesis's method, the whole similarity) is fitted on the most neutral of
its own frames. Two recordings of one subject then disagree on where rest is and how large the
lips are: on the cached ``table51-pipeline`` data (preset ``default``, seed 0) the training
recording's scale was 1.036 and the test utterance's 0.938, 10 % apart, although the subject and
the rig are the same. The thesis normalised all the data of its one subject with one transform.

:func:`renormalize` re-runs the normalisation and the least-strain fields of a reconstruction
(from its triangulated lab points; no tracking again) with the reference of another one, e.g.
the training recording's (:func:`reference_similarity`). The reference still comes from
training frames only (issue 16): the other recording's own reference frame.

Measured on the cached ``table51-pipeline`` recordings (subject seeds 0-4; training 150 frames,
test utterance 40 frames, rendered at 640x480), the per-marker constant offset of the marker
displacements against the truth (each marker's mean error over its accepted sightings, RMS over the
markers, mm). How far the test utterance's offset is from the training recording's, with its own
reference / with the training one: 6.09 / 3.91, 4.95 / 2.44, 4.66 / 2.23, 1.19 / 0.78,
1.07 / 0.78 (mean 3.59 / 2.03). The test offset itself: 5.11 / 4.72, 4.63 / 2.87, 3.87 / 3.13,
2.82 / 3.42, 4.05 / 4.64 (mean 4.10 / 3.76). The scales: training 1.036, 1.005, 1.046, 0.940,
0.921; the utterance's own 0.938, 0.907, 0.949, 0.962, 0.937. What remains is the training
reference's own error (its scale is fitted on a speaking frame) and the displacement being taken
from the model's rest, not the subject's (the subject's rest markers are 2.2-2.7 mm RMS from the
model's on these seeds), which training and test share.

For another subject this is the wrong reference: its rest shape and size are its own, so the
training subject's scale misreads its shape as motion. It keeps its own reference (fitted on its
own most neutral frame, or on frames named as rest), as a new person is calibrated.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from lipgen._validate import as_float_array
from lipgen.recon.normalize import lip_subsets, normalize_markers
from lipgen.recon.similarity import Similarity
from lipgen.recon.steps import reach_fields

__all__ = ["reference_similarity", "renormalize"]


def reference_similarity(recon) -> Similarity:
    """The normalisation's reference of a :class:`~lipgen.recon.pipeline.Reconstruction`.

    Parameters
    ----------
    recon : Reconstruction
        Its ``similarity`` (4, 4) is ``[[s R, t], [0, 1]]`` and ``info["normalisation"]["scale"]`` is s.

    Returns
    -------
    Similarity
        Scale s, rotation R (3, 3), translation t (3,) (model frame, mm).
    """
    S = np.asarray(recon.similarity, dtype=np.float64)
    if S.shape != (4, 4) or not np.all(np.isfinite(S)):
        raise ValueError(f"recon.similarity must be a finite (4, 4) matrix, got shape {S.shape}")
    s = float(recon.info.get("normalisation", {}).get("scale", np.cbrt(np.linalg.det(S[:3, :3]))))
    if not s > 0:
        raise ValueError(f"the reconstruction's normalisation scale must be > 0, got {s}")
    return Similarity(s, S[:3, :3] / s, S[:3, 3].copy())


def renormalize(recon, reference, physics=None, rest=None):
    """``recon`` normalised with the reference of another reconstruction, its fields re-reached.

    Parameters
    ----------
    recon : Reconstruction
        The recording to express in the reference's frame (its ``lab_points`` (F, P + 1, 3), the
        nose last, and ``visible`` (F, P) are used; tracking is not repeated).
    reference : Reconstruction or Similarity
        A reconstruction of the same subject on the same rig (e.g. the training recording), or its
        :func:`reference_similarity`. Passing ``recon`` itself gives its own result again.
    physics : lipgen.fem.Physics, optional
        Of the model mesh ``recon`` was reconstructed with (built from its ``mesh_source`` if None).
    rest : (P, 3) float or callable, optional
        The rest markers (model frame, mm) the fields are reached from; NaN rows fall back to the
        model's. A callable is given the renormalised markers (F, P, 3) and the measured mask
        (F, P) and returns them (e.g. :func:`lipgen.recon.rest.recording_rest`). None (default): the
        model's rest markers.

    Returns
    -------
    Reconstruction
        ``recon`` with new ``markers`` (F, P, 3), ``fields`` (F, n, 3), ``similarity`` (4, 4) and
        ``rotations`` (F, 3, 3); ``info["normalisation"]`` records the reference
        (``reference_frame`` -1, ``reference_from`` the reference's dataset); with ``rest`` given,
        ``info["rest"]`` is the rest used.
    """
    from lipgen._threads import blas_threads

    sim = reference if isinstance(reference, Similarity) else reference_similarity(reference)
    info = recon.info
    norm_info = info.get("normalisation", {})
    method = norm_info.get("method", "least-force")
    if physics is None:
        from lipgen.fem import Physics
        from lipgen.recon.modelmesh import model_mesh

        physics = Physics(model_mesh(info["mesh_source"]))
    mesh = physics.mesh
    P = len(mesh.markers)
    points = np.asarray(recon.lab_points, dtype=np.float64)
    if points.ndim != 3 or points.shape[1:] != (P + 1, 3) or recon.visible.shape != (len(points), P):
        raise ValueError(f"recon.lab_points must be (F, {P + 1}, 3) and recon.visible (F, {P}) for the model "
                         f"mesh's {P} markers, got {points.shape} and {recon.visible.shape}")
    upper, lower = lip_subsets(mesh.marker_names)
    M = mesh.vertices[mesh.markers]
    with blas_threads(1):  # per-frame poses and reaches (lipgen._threads)
        norm = normalize_markers(points[:, :P], points[:, P], upper, lower, M, model_nose=mesh.nose,
                                 visible=recon.visible, method=method, physics=physics, reference=sim)
        outliers = np.zeros(recon.visible.shape, bool) if norm.outliers is None else norm.outliers
        min_visible = int(info.get("settings", {}).get("min_visible", 4))
        measured = recon.visible & ~outliers
        base = M if rest is None else _rest_markers(rest, norm.markers, measured, M)
        fields = reach_fields(physics, norm.markers - base, measured, mesh.markers, min_visible)
    S = np.eye(4)
    S[:3, :3] = norm.similarity.scale * norm.similarity.rotation
    S[:3, 3] = norm.similarity.translation
    source = ("a given similarity" if isinstance(reference, Similarity)
              else reference.info.get("dataset", "a given reconstruction"))
    new_info = {**info, "normalisation": {**norm_info, "scale": norm.similarity.scale, "reference_frame": -1,
                                          "reference_from": source, "fit_rms_mm": float("nan"),
                                          "borrowed_frames": int(norm.borrowed.sum()),
                                          "outliers": np.argwhere(outliers).tolist()}}
    # the rest these fields are measured from, never the input's (a caller that knows where a given
    # rest came from, e.g. restsource.measured_from_rest, records its source again)
    new_info["rest"] = base.tolist()
    new_info["rest_source"] = {"kind": "model" if rest is None else "given", "frames": None, "fallback": []}
    return dataclasses.replace(recon, fields=fields, markers=norm.markers, similarity=S,
                               rotations=norm.rotations, info=new_info)


def _rest_markers(rest, markers, measured, model_markers):
    """(P, 3) float: ``rest`` checked (or computed from ``markers``), NaN rows from the model's."""
    if callable(rest):
        rest = rest(markers, measured)
    rest = as_float_array(rest, "rest", model_markers.shape, finite=False)
    return np.where(np.isfinite(rest), rest, model_markers)
