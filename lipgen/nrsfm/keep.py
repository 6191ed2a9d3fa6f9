"""Whether ``dai-ba`` keeps its refinement: a lower reprojection error without inflated depth.

Bundle adjustment (:func:`lipgen.nrsfm.refine.bundle_adjust`) starts from ``dai``'s rotations with K
basis shapes fitted to them, and lowers the reprojection error of the observed points. Under
orthography the image fixes x and y; what a K-shape model cannot hold it can push into depth, and
the reprojection error alone then cannot tell a better reconstruction from one whose depth inflates
(on held-out bodies such refinements reached e3D 1.4-4.4 with a depth spread 4.7 times the truth's).
The refinement is kept when

- its reprojection error is below its start's (an accepted step was made),
- its depth is neither much deeper nor much rougher than that of ``dai``'s answer (the trace-norm
  shapes, the least depth that reprojects exactly): the depth ratio (RMS depth over RMS image
  spread of the camera-frame shapes, :func:`lipgen.nrsfm.plausibility.depth_ratio`) and the depth
  roughness (mean squared second time difference, :func:`lipgen.nrsfm.plausibility.roughness`) at
  most :data:`DEPTH_KEEP` and :data:`ROUGHNESS_KEEP` times ``dai``'s, and
- it stays plausible against Dai's trace-norm shapes (:func:`lipgen.nrsfm.plausibility.plausible`);

otherwise ``dai``'s answer is returned as it is. The truth is never used. The least trace norm is a
bias towards shallow depth (the truth's depth ratio is 1.063 on jaws against 0.849 for ``dai`` at
K = 2, and 0.3707 on drink against 0.364 at K = 12), so some deepening is
allowed; what separates a refinement that finds the motion from one that fits the model's
shortfall with depth is that the latter's depth jitters from frame to frame.

The rule before asked for strictly smoother rotations and no deeper depth than ``dai``'s; it refused
refinements that were better by the truth (drink K = 12: 0.0201 -> 0.0116, rotations 1.07 times
rougher; jaws K = 2: 0.2325 -> 0.1332, depth ratio 1.21 times ``dai``'s).
"""

from __future__ import annotations

from lipgen.nrsfm.plausibility import plausible

__all__ = ["keep_refinement", "DEPTH_KEEP", "ROUGHNESS_KEEP"]

DEPTH_KEEP = 1.5
"""Largest depth ratio of a kept refinement, as a multiple of ``dai``'s answer's."""

ROUGHNESS_KEEP = 1.5
"""Largest depth roughness of a kept refinement, as a multiple of ``dai``'s answer's.

Both limits were set on 15 refinements of development bodies (80 frames: seeds 300-303, 400, 405 and
406 at K = 4 and 8, 407 at K = 4) with drink K = 12 and jaws K = 2 and 3 in view, never on the fresh
bodies (1100-1119). Refinements better
by the truth had (depth roughness, depth ratio) of (1.04, 1.02) (drink K = 12) and (0.67, 1.21)
(jaws K = 2) times ``dai``'s; plausible ones that were worse, (2.12, 1.19) (walk-400 K = 8) and
(2.62, 1.97) (dance-302 K = 4); the blow-ups (e3D 1.5-18) had a depth ratio of 1.5-48 times or a
depth roughness of 5-55 times ``dai``'s."""


def keep_refinement(history, refined: dict, start: dict, reference: dict) -> bool:
    """The keep rule of ``dai-ba`` (see the module docstring).

    Parameters
    ----------
    history : sequence of float
        The refinement's cost after each accepted step, its start's first
        (:func:`lipgen.nrsfm.refine.bundle_adjust`).
    refined, start, reference : dict
        :func:`lipgen.nrsfm.plausibility.shape_figures` (``depth_ratio``, ``depth_roughness``) of the
        refined shapes, of ``dai``'s answer (returned if the refinement is refused), and of Dai's
        trace-norm shapes.

    Returns
    -------
    bool
        True to keep the refinement.
    """
    if len(history) < 2 or not history[-1] < history[0]:
        return False
    return bool(refined["depth_ratio"] <= DEPTH_KEEP * start["depth_ratio"]
                and refined["depth_roughness"] <= ROUGHNESS_KEEP * start["depth_roughness"]
                and plausible(refined, reference))
