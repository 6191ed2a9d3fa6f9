"""One view of a stereo reconstruction as NRSfM tracks: monocular NRSfM on a recording, no truth.

The tracker's pixels of one view (``Reconstruction.uv``) become weak-perspective tracks as in
:func:`lipgen.nrsfm.dataset_tracks`, but with the calibrated view camera and the mean depth of the
triangulated marks instead of the truth: normalised image coordinates times that one depth (mm).
"""

from __future__ import annotations

import numpy as np

from lipgen.errors import DatasetError
from lipgen.rig.camera import VIEWS

__all__ = ["reconstruction_tracks"]


def reconstruction_tracks(recon, view: str = "real", min_frames: int = 3) -> dict:
    """Weak-perspective tracks of one view of a :class:`lipgen.recon.pipeline.Reconstruction`.

    Marks tracked in fewer than ``min_frames`` frames and then frames with fewer than 3 tracked
    marks are left out (NRSfM cannot place them), and named in the result.

    Returns
    -------
    dict
        ``W`` (2F', P') mm (NaN where not seen), ``visible`` (F', P') bool, ``marks`` (P',) names,
        ``frames`` (F',) int, ``dropped_marks`` [(name, frames seen)], ``dropped_frames`` [int],
        ``depth`` (mm).
    """
    from lipgen.recon.track import LOST

    if view not in VIEWS:
        raise ValueError(f"view must be one of {VIEWS}, got {view!r}")
    v = VIEWS.index(view)
    cam = recon.lab_calibration.views[v]
    uv = recon.uv[v]
    seen = (recon.status[v] != LOST) & np.isfinite(uv).all(-1)
    X = recon.lab_points.reshape(-1, 3)
    X = X[np.isfinite(X).all(1)]
    if len(X) == 0:
        raise DatasetError("the reconstruction triangulated no mark: no depth for weak perspective")
    depth = float(np.mean((X @ cam.R.T + cam.t)[:, 2]))
    names = list(recon.info.get("marker_names", [])) + ["nose"]
    names += [str(j) for j in range(len(names), seen.shape[1])]
    count = seen.sum(0)
    keep = np.flatnonzero(count >= min_frames)
    frames = np.flatnonzero(seen[:, keep].sum(1) >= 3)
    if len(keep) < 3 or len(frames) < 2:
        raise DatasetError(f"the {view} view has only {len(keep)} marks tracked in {min_frames}+ frames and "
                           f"{len(frames)} frames with 3 of them: too little for NRSfM")
    vis = seen[np.ix_(frames, keep)]
    xy = cam.normalized(np.where(vis[..., None], uv[np.ix_(frames, keep)], 0.0)) * depth
    F, P = vis.shape
    W = xy.transpose(0, 2, 1).reshape(2 * F, P).copy()
    W[np.repeat(~vis, 2, axis=0)] = np.nan
    return {"W": W, "visible": vis, "marks": [names[j] for j in keep], "frames": frames,
            "dropped_marks": [(names[j], int(count[j])) for j in np.flatnonzero(count < min_frames)],
            "dropped_frames": sorted(set(range(len(seen))) - set(frames.tolist())), "depth": depth}
