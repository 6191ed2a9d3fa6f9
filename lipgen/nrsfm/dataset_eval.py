"""NRSfM on one view of a synthetic lipgen dataset, scored against the true 3D marks.

The rig's cameras are perspective; the factorisation methods assume (scaled) orthography. The
tracks are therefore built as *weak perspective*: each observed pixel is turned into normalised
image coordinates ``(x/z, y/z)`` (intrinsics and distortion removed) and multiplied by one
depth for the whole sequence, the mean true depth of the marks. That per-sequence depth fixes
only the unit (mm); a monocular reconstruction cannot know absolute scale. What remains of
perspective (depth relief of the mouth against the camera distance, and the head moving toward
the camera) is model error the score includes: ``relief`` in the result says how large it is.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from lipgen._io import load_npz
from lipgen.errors import DatasetError
from lipgen.nrsfm.core import DEFAULT_METHOD, reconstruct
from lipgen.nrsfm.metrics import e3d, flat_e3d

__all__ = ["dataset_tracks", "evaluate_on_dataset"]

log = logging.getLogger(__name__)


def dataset_tracks(path, view: str = "real", marks=None, uv=None, seen=None):
    """Weak-perspective tracks of one view of a dataset, with the camera-frame truth.

    Parameters
    ----------
    path : path
        Dataset folder written by ``lipgen generate``.
    view : str
        ``"real"`` or ``"virtual"`` (the mirror view).
    marks : sequence of int, optional
        Mark indices to use (default all: 16 markers then the nose).
    uv : (F, P_all, 2) float, optional
        Measured pixel tracks of this view (e.g. ``Reconstruction.uv[v]`` from ``track.py``), in
        the same corrected view coordinates as the truth's ``uv``, for all marks in dataset order.
        Default: the truth's exact projections.
    seen : (F, P_all) bool, optional
        Where ``uv`` holds a sighting (required with ``uv``).

    Returns
    -------
    dict
        ``W`` (2F, P) weak-perspective tracks in mm (unobserved entries NaN), ``W_all`` the same
        for every mark (occluded ones included, from the truth), ``visible`` (F, P),
        ``S`` (3F, P) true marks in the view camera's frame (mm), ``depth`` (mean true depth, mm),
        ``relief`` (RMS over frames of the marks' depth spread divided by their depth),
        ``pixels_rms`` (RMS distance, px, between the tracks and the truth's projections: ~0 for
        the truth's own pixels, the tracking error for measured ones).
    """
    from lipgen.dataset.layout import FRAME_KIND, SCHEMA, Dataset

    ds = Dataset(path)
    views = list(ds.manifest["views"])
    if view not in views:
        raise ValueError(f"view must be one of {views}, got {view!r}")
    v = views.index(view)
    cam = ds.rig.views[v]
    if ds.missing():
        raise DatasetError(f"{path}: frames {ds.missing()[:5]}... are not written; finish the dataset "
                           "with lipgen generate --resume")
    measured = uv
    uv_truth, X, vis = [], [], []
    for f in ds.manifest["frames"]:
        truth = load_npz(Path(path) / f["truth"], FRAME_KIND, SCHEMA)
        uv_truth.append(truth["uv"][v])
        X.append(truth["marks_world"])
        vis.append(truth["visible"][v])
    uv, X, vis = np.array(uv_truth, float), np.array(X, float), np.array(vis, bool)
    if measured is not None:
        uv, vis = _measured_tracks(measured, seen, uv.shape)
    if marks is not None:
        idx = np.asarray(marks, dtype=int)
        uv, X, vis = uv[:, idx], X[:, idx], vis[:, idx]
    X_cam = X @ cam.R.T + cam.t                               # (F, P, 3) view camera frame, mm
    depth = float(X_cam[..., 2].mean())
    check = cam.project(X)
    pixels_rms = float(np.sqrt(np.nanmean(np.sum((check - uv) ** 2, axis=-1))))  # per point, px
    xy = cam.normalized(np.where(vis[..., None], uv, 0.0)) * depth  # weak perspective, mm
    F, P = vis.shape
    W = xy.transpose(0, 2, 1).reshape(2 * F, P).copy()
    W[np.repeat(~vis, 2, axis=0)] = np.nan
    # every mark, seen or not: the pinhole projection of the truth (what uv holds where defined)
    W_all = (X_cam[..., :2] / X_cam[..., 2:] * depth).transpose(0, 2, 1).reshape(2 * F, P)
    z = X_cam[..., 2]
    relief = float(np.sqrt(np.mean((z.std(axis=1) / z.mean(axis=1)) ** 2)))
    S = X_cam.transpose(0, 2, 1).reshape(3 * F, P)
    return {"W": W, "W_all": W_all, "visible": vis, "S": S, "depth": depth, "relief": relief,
            "pixels_rms": pixels_rms}


def _measured_tracks(uv, seen, shape):
    """Check tracker output against the truth's shape; unseen entries become NaN."""
    uv = np.asarray(uv, dtype=float)
    if seen is None:
        raise ValueError("measured tracks need `seen` (F, P) bool: where each mark was sighted")
    seen = np.asarray(seen, dtype=bool)
    if uv.shape != shape or seen.shape != shape[:2]:
        raise DatasetError(f"measured tracks have uv {uv.shape} and seen {seen.shape}, but the dataset "
                           f"has {shape[0]} frames x {shape[1]} marks: (F, P, 2) and (F, P) expected; "
                           "were the tracks made from this dataset?")
    seen = seen & np.isfinite(uv).all(axis=-1)
    return np.where(seen[..., None], uv, np.nan), seen


def evaluate_on_dataset(path, view: str = "real", k: int | str = 2, method: str = DEFAULT_METHOD,
                        marks=None, use_visibility: bool = True, uv=None, seen=None) -> dict:
    """Reconstruct one view of a dataset by NRSfM and score it against the true marks.

    Parameters
    ----------
    path : path
        Dataset folder.
    view : str
        ``"real"`` or ``"virtual"``.
    k : int or "auto"
        Number of basis shapes, or ``"auto"``: chosen by the method (:func:`lipgen.nrsfm.reconstruct`).
    method : str
        See :data:`lipgen.nrsfm.METHODS`.
    marks : sequence of int, optional
        Marks to use (default all 17: markers and nose).
    use_visibility : bool
        Treat marks the truth flags as not visible in this view as missing (default). If False,
        every projection is used, occluded or not (truth projections only).
    uv, seen : (F, P_all, 2) float and (F, P_all) bool, optional
        Measured tracks (``track.py``) to use instead of the truth's projections; see
        :func:`dataset_tracks`.

    Returns
    -------
    dict
        ``e3d`` (benchmark metric), ``flat_e3d`` (the same for the tracks the method was given,
        with zero depth and the truth's projection where they have no sighting: the score of not
        reconstructing depth at all from the same input), ``mean_error_mm`` (mean point distance
        after the same alignment, in mm), ``frames``, ``points``, ``observed_fraction``, ``k``, ``method``,
        ``view``, ``depth_supported`` (False: the method returned the flat answer),
        ``reprojection_rms_mm``, ``depth_mm``, ``relief``, ``tracks`` (which tracks
        were used), ``tracking_rms_px`` (their error against the truth; 0 for the truth's own
        projections), and ``markdown`` (a snippet for the end-to-end report, with why the depth was kept
        or dropped).
    """
    data = dataset_tracks(path, view, marks, uv=uv, seen=seen)
    W, visible, S = data["W"], data["visible"], data["S"]
    source = "tracked by `track.py`" if uv is not None else "the truth's projections"
    if not use_visibility and uv is None:
        W, visible = data["W_all"], np.ones_like(visible)
    rec = reconstruct(W, k, method=method, visible=None if visible.all() else visible)
    err = e3d(S_est=rec.S, S_true=S)
    # Baseline: no depth at all, the same tracks the method was given with z = 0 (measured tracks
    # carry the tracker's error, and a baseline without it would blame NRSfM for the tracking),
    # with the truth's projection where the tracks have no sighting.
    F, P = visible.shape
    flat_err = flat_e3d(W, S, fill=data["W_all"])
    s = float(np.mean(np.std(S, axis=1)))
    result = {"e3d": err, "flat_e3d": flat_err, "depth_supported": bool(rec.depth_supported),
              "mean_error_mm": err * s, "frames": F, "points": P,
              "observed_fraction": float(visible.mean()), "k": rec.k, "method": method, "view": view,
              "reprojection_rms_mm": rec.reprojection_rms, "depth_mm": data["depth"],
              "relief": data["relief"], "tracks": source,
              "tracking_rms_px": data["pixels_rms"] if uv is not None else 0.0}
    result["markdown"] = (
        f"**Monocular NRSfM ({method}, K = {rec.k}{' (chosen)' if isinstance(k, str) else ''})"
        f" on the {view} view**: "
        f"{F} frames x {P} marks "
        f"({100 * result['observed_fraction']:.1f} % observed). e3D = **{err:.4f}** "
        f"(mean 3D error {result['mean_error_mm']:.3f} mm after one global rotation/reflection; "
        f"a flat reconstruction, the tracks with zero depth, scores {flat_err:.4f}), "
        f"RMS reprojection {rec.reprojection_rms:.3f} mm. Tracks are {source}"
        + (f" ({data['pixels_rms']:.2f} px RMS from the truth)" if uv is not None else "")
        + f", made weak-perspective (normalised coordinates x mean depth {data['depth']:.0f} mm); the marks' "
        f"depth relief is {100 * data['relief']:.2f} % of their depth, so perspective is part of "
        "the error, and the depth sign is fixed only up to one global reflection."
        + _depth_sentence(rec))
    return result


def _depth_sentence(rec) -> str:
    """Why the reconstruction kept its depth or returned the flat answer, from ``info["depth_support"]``
    (empty where the method makes no such test), with how far the views turn: a few degrees leave
    depth weakly observable whatever the test says."""
    support = rec.info.get("depth_support")
    if not support:
        return ""
    verdict = "kept" if rec.depth_supported else "not supported by the tracks: the flat answer (zero depth)"
    span = support.get("spread_deg", float("nan"))
    turn = f"; the views turn by {span:.1f} deg (median from their mean direction)" if np.isfinite(span) \
        else ""
    return f" Depth {verdict}: {support.get('reason', 'no reason recorded')}{turn}."
