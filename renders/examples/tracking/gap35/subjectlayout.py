"""The subject's own marker layout, measured from a first tracking pass, for tracking again.

Every identity decision of the tracker (the first frame's labels, acquisitions, the 3-D checks, the
one-view pairing) compares dots with where the marker layout puts a marker. That layout is the
model's markers at rest. A ``hard`` subject has its own lip shape and dot placement, so the layout
placed on right markers puts the others 2-5 mm from their points while the markers lie about 5 mm
apart (:mod:`lipgen.recon.grow`). A first pass over the clip, though, sees most markers in both views
in most frames: the subject's own layout can be measured from it. :func:`subject_layout` aligns each
frame's accepted 3-D points to a reference by a similarity (generalised Procrustes, started from the
model's layout) and takes each marker's median over the frames; a marker seen in fewer than ``least``
frames keeps the model's position. The result is put back in the model's place by one similarity, so
that it projects where the model's layout did (:func:`lipgen.recon.steps.expected_projections`).

It is the median shape over the clip, not the rest: a clip's mouth opens and closes. As a layout for
predicting one marker from the others it is still nearer the subject than the model's rest is. A
marker the first pass held on a wrong dot for most of the clip moves its layout point there; the
second pass then keeps that error.
"""

from __future__ import annotations

import numpy as np

from lipgen._validate import as_float_array
from lipgen.recon.stereo_init import _similarity_3d

__all__ = ["SUBJECT_LAYOUT_LEAST", "subject_layout"]

SUBJECT_LAYOUT_LEAST = 10
"""Frames a marker must be accepted in for its own layout point to be measured."""

_MIN_ALIGN = 6      # points a frame needs for its similarity (a 3-D similarity has 7 parameters)


def _apply(T: np.ndarray, X: np.ndarray) -> np.ndarray:
    return X @ T[:3, :3].T + T[:3, 3]


def subject_layout(rest, points, seen, least: int = SUBJECT_LAYOUT_LEAST, rounds: int = 3
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Each marker's median position over the clip, in the frame of the model's layout.

    Parameters
    ----------
    rest : (P, 3) float
        The model's layout (the markers at rest, the nose last), mm.
    points : (F, P, 3) float
        Each frame's triangulated points, mm; read where ``seen``.
    seen : (F, P) bool
        Accepted points (both views, rays within the gap limit).
    least : int
        Frames a marker needs to be measured.
    rounds : int
        Procrustes rounds (each aligns every frame to the last round's median).

    Returns
    -------
    layout : (P, 3) float
        The measured layout, placed on ``rest`` by one similarity over the measured markers; the others
        are ``rest``'s points.
    measured : (P,) bool
        The markers whose point was measured.
    """
    rest = as_float_array(rest, "rest", (None, 3))
    P = len(rest)
    points = as_float_array(points, "points", (None, P, 3), finite=False)
    seen = np.asarray(seen, dtype=bool)
    if seen.shape != points.shape[:2]:
        raise ValueError(f"seen must have shape {points.shape[:2]} (frames, points), got {seen.shape}")
    if isinstance(least, bool) or int(least) != least or least < 1:
        raise ValueError(f"least must be a whole number of frames >= 1, got {least!r}")
    seen = seen & np.all(np.isfinite(points), axis=2)
    frames = np.flatnonzero(seen.sum(1) >= _MIN_ALIGN)
    measured = seen[frames].sum(0) >= least
    if measured.sum() < _MIN_ALIGN:
        return rest.copy(), np.zeros(P, dtype=bool)
    ref = rest.copy()
    for _ in range(rounds):
        aligned = np.full((len(frames), P, 3), np.nan)
        for n, f in enumerate(frames):
            use = seen[f]
            T = _similarity_3d(points[f, use], ref[use])
            aligned[n, use] = _apply(T, points[f, use])
        median = np.nanmedian(aligned[:, measured], axis=0)
        ref = rest.copy()
        ref[measured] = _apply(_similarity_3d(median, rest[measured]), median)
    return ref, measured
