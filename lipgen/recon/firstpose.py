"""The first frame's dots matched to the markers, and matched again from a re-posed layout where that fails.

The first frame is matched to the markers' layout at rest, projected through the calibrated views
(``expected``). Where the subject's head in the first frame is far from that pose, the 2-D match
fails in both views: on ``hard`` 58 and 64 frame 0 the layout at rest lies 30-50 px from the subject's
dots, turned, and even the direct view (16 of 17 marks detected) has 3 of 12 matches right; with the
mirror's faint dots under the fixed floor as well, no marker is left matched in both views
(``renders/examples/tracking/collapse19_first_frame.md``). Placing the layout where the truth puts
it (a diagnosis only) with the mirror's floor at 0.05 leaves 7 markers right in both views on
``hard`` 56, 58 and 64.

So, where the usual match leaves fewer than ``first_frame_repose`` markers matched in both views,
both views are detected again at the tracker's least floor, the layout is moved in 3-D to where
their dot pairs place it (:func:`lipgen.recon.stereo_init.repose_layout`: a translation vote, then
a similarity), and the first frame is matched again from its projection, with one view's dots at
the least floor (the view that pairs more markers: which view is pale is not known). The retry is
kept only when it leaves more markers matched in both views.
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from lipgen.recon.dots import detect_dots
from lipgen.recon.firstframe import first_frame_dots, match_view
from lipgen.recon.grow import check_first_frame, paired_markers
from lipgen.recon.stereo_init import layout_dots, repose_layout
from lipgen.rig.camera import VIEWS

__all__ = ["match_first_frame_views", "first_frame"]

log = logging.getLogger(__name__)


def match_first_frame_views(detected, exp, settings, cameras=None, rest_points=None, names=None,
                            covariance=None) -> tuple[list[np.ndarray], np.ndarray]:
    """Each view's first-frame dots matched to the layout ``exp (2, P, 2)``, then checked between the views.

    ``detected`` is each view's (uv (k, 2), strength (k,)); ``settings`` a ReconstructSettings.
    Returns the (virtual, real) (P, 2) matches (NaN: none) and the (P,) markers dropped for their
    ray gap (see :func:`lipgen.recon.grow.check_first_frame`).
    """
    found = [d[0] for d in detected]
    keep = [np.ones(len(d), dtype=bool) for d in found]
    if cameras is not None and rest_points is not None and settings.first_frame_lures:
        keep = layout_dots(found[0], found[1], cameras, rest_points)
    inits = []
    for v, dots in enumerate(found):
        init = np.full(exp[v].shape, np.nan)
        match = match_view(dots, detected[v][1], exp[v], settings.init_gate, settings.robust_first_frame,
                           settings.first_frame_dark)
        # Matched on all dots (a dot removed would leave its marker to a neighbour's), but a match
        # on a lure is dropped.
        lure = np.zeros(len(match), dtype=bool)       # (a view with no dots has no index to look up)
        lure[match >= 0] = ~keep[v][match[match >= 0]]
        if lure.any():
            log.info("%s view, first frame: %d match(es) on dots no other-view dot places near the layout "
                     "dropped", VIEWS[v], int(lure.sum()))
            match[lure] = -1
        init[match >= 0] = dots[match[match >= 0]]
        inits.append(init)
    bad = np.zeros(len(exp[0]), dtype=bool)
    if cameras is not None:
        inits, bad = check_first_frame(inits, found, cameras, settings.max_ray_gap,
                                       rest_points if settings.first_frame_layout else None,
                                       settings.first_frame_grow, names, covariance,
                                       settings.first_frame_one_view)
    return inits, bad


def first_frame(views, exp, settings, cameras=None, rest_points=None, names=None, covariance=None):
    """The first frame's detection and matches (see the module docstring).

    Parameters
    ----------
    views : (virtual, real) (H, W) or (H, W, 3) images
    exp : (2, P, 2) float
        The layout at rest in each view, px (NaN: not projected). The trackers keep it as their
        reference even where the match was made from the re-posed layout.
    settings : ReconstructSettings
    cameras, rest_points, names, covariance
        As :func:`lipgen.recon.steps.track_raw_frames`.

    Returns
    -------
    inits : (virtual, real) (P, 2) float
    bad : (P,) bool
    found : (virtual, real) (k, 2) float
        The dots the matches were made on.
    """
    dots = settings.tracker.dots
    detected = first_frame_dots(views, dots, exp, settings.init_gate, settings.robust_first_frame,
                                settings.first_frame_dark, settings.first_frame_floor,
                                settings.tracker.floor_min)
    inits, bad = match_first_frame_views(detected, exp, settings, cameras, rest_points, names,
                                         covariance)
    found = [d[0] for d in detected]
    if settings.first_frame_repose is None or cameras is None or rest_points is None:
        return inits, bad, found
    n = int(paired_markers(inits).sum())
    if n >= settings.first_frame_repose:
        return inits, bad, found
    low = [detect_dots(img, replace(dots, min_contrast=settings.tracker.floor_min)) for img in views]
    moved = repose_layout(low[0][0], low[1][0], cameras, rest_points)
    if moved is None:
        return inits, bad, found
    exp2 = np.stack([cam.project(moved) for cam in cameras])
    exp2[~np.isfinite(exp)] = np.nan  # a marker the caller does not project stays unmatched
    best = None
    for pale in range(2):   # which view is the pale one is not known: the one that pairs more markers
        retry = [low[v] if v == pale else detected[v] for v in range(2)]
        got = match_first_frame_views(retry, exp2, settings, cameras, rest_points, names, covariance)
        n2 = int(paired_markers(got[0]).sum())
        if best is None or n2 > best[0]:
            best = (n2, pale, got, [d[0] for d in retry])
    n2, pale, (inits2, bad2), found2 = best
    if n2 <= n:
        log.info("first frame: the re-posed layout not taken (%d marker(s) matched in both views, "
                 "against %d)", n2, n)
        return inits, bad, found
    log.info("first frame: %d marker(s) matched in both views; from the re-posed layout, with the %s view's "
             "floor at %.3f: %d", n, VIEWS[pale], settings.tracker.floor_min, n2)
    return inits2, bad2, found2
