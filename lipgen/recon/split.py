"""The held-out tail of a sequence: which frames are test frames (thesis: 140 train + 10 test).

It lives with the reconstruction because the normalisation must choose its reference frame from
the training frames only (no test frame may shape the training data); ``lipgen train`` and
``lipgen evaluate`` use the same rule.
"""

from __future__ import annotations

import numpy as np

__all__ = ["default_test_frames", "training_candidates"]


def default_test_frames(n_frames: int) -> int:
    """The held-out tail: 10 frames as in the thesis (140 + 10), a fifth of short sequences."""
    return 10 if n_frames >= 50 else max(2, n_frames // 5)


def training_candidates(n_frames: int, test_frames: int | None = None, reference_frames=None) -> np.ndarray:
    """(k,) int frames the normalisation may take its reference frame from.

    ``reference_frames`` named by the user win (each in ``[0, n_frames)``); otherwise every frame
    before the last ``test_frames`` (default :func:`default_test_frames`).
    """
    F = int(n_frames)
    if reference_frames is not None:
        idx = np.unique(np.asarray(list(reference_frames), dtype=np.int64))
        bad = idx[(idx < 0) | (idx >= F)]
        if len(idx) == 0 or len(bad):
            raise ValueError(f"reference frames must be frames in [0, {F}), got "
                             + (f"{len(bad)} of {len(idx)} outside it (e.g. {int(bad[0])})" if len(bad) else
                                "none"))
        return idx
    T = default_test_frames(F) if test_frames is None else int(test_frames)
    if not 1 <= T < F:
        raise ValueError(f"test_frames must be in [1, {F - 1}] for {F} frames, got {T}")
    return np.arange(F - T)
