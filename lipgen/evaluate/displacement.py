"""The reconstructed marker displacements against the true ones, and their constant offset.

A reconstruction measures each marker's displacement from a rest (:mod:`lipgen.recon.restsource`);
the truth measures it from the subject's own rest. A rest that is not the subject's adds the same
error to every frame of a marker: its **constant offset** (the marker's mean error over the frames
it was measured in). :func:`displacement_error` reports the RMS error, the offset (RMS over the
markers of each marker's mean error) and the error once the offset is taken out (what no rest could
remove: tracking, triangulation and normalisation noise).
"""

from __future__ import annotations

import warnings

import numpy as np

from lipgen._validate import as_float_array

__all__ = ["displacement_error"]


def displacement_error(markers, measured, rest, true_marks, true_rest, frames=None) -> dict:
    """RMS error of the marker displacements, their per-marker constant offset, and the rest, mm.

    Parameters
    ----------
    markers : (F, P, 3) float
        Normalised markers, model frame, mm (NaN where not measured).
    measured : (F, P) bool
        The sightings that count (e.g. :func:`lipgen.recon.rest.measured_markers`).
    rest : (P, 3) float
        The rest the reconstruction measures from (:func:`lipgen.recon.restsource.rest_markers`).
    true_marks : (F, P, 3) float
        The true marks in the model frame, mm.
    true_rest : (P, 3) float
        The subject's true rest marks in the model frame, mm.
    frames : (k,) int, optional
        The frames scored (default all).

    Returns
    -------
    dict
        ``rms_mm`` (over the measured sightings), ``offset_rms_mm`` (RMS over the markers measured at
        least once of each one's mean error), ``after_offset_rms_mm``, ``rest_rms_mm`` (the rest
        against the true rest, RMS over the markers), ``per_marker_offset_mm`` (P,) the length of
        each marker's mean error (NaN: never measured), ``sightings``.
    """
    X = as_float_array(markers, "markers", (None, None, 3), finite=False)
    F, P = X.shape[:2]
    m = np.asarray(measured, dtype=bool)
    if m.shape != (F, P):
        raise ValueError(f"measured must have shape {(F, P)}, got {m.shape}")
    R = as_float_array(rest, "rest", (P, 3))
    Y = as_float_array(true_marks, "true_marks", (F, P, 3))
    R0 = as_float_array(true_rest, "true_rest", (P, 3))
    idx = np.arange(F) if frames is None else np.asarray(frames, dtype=np.int64)
    err = (X[idx] - R) - (Y[idx] - R0)
    ok = m[idx] & np.all(np.isfinite(err), axis=-1)
    err = np.where(ok[..., None], err, np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a marker never measured: NaN, on purpose
        offset = np.nanmean(err, axis=0)
        length = np.linalg.norm(offset, axis=-1)
        seen = ok.any(axis=0)
        rms = float(np.sqrt(np.nanmean(np.sum(err**2, axis=-1)))) if ok.any() else float("nan")
        after = (float(np.sqrt(np.nanmean(np.sum((err - offset) ** 2, axis=-1)))) if ok.any()
                 else float("nan"))
        off_rms = float(np.sqrt(np.mean(length[seen] ** 2))) if seen.any() else float("nan")
    return {"rms_mm": rms, "offset_rms_mm": off_rms, "after_offset_rms_mm": after,
            "rest_rms_mm": float(np.sqrt(np.mean(np.sum((R - R0) ** 2, axis=1)))),
            "per_marker_offset_mm": length.tolist(), "sightings": int(ok.sum())}
