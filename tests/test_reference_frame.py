"""The normalisation's reference frame comes from the training frames only (no test frame)."""

import numpy as np
import pytest

from lipgen.recon.normalize import normalize_markers
from lipgen.recon.similarity import most_neutral_frame
from lipgen.recon.split import default_test_frames, training_candidates


def _frames():
    """Markers of 6 frames; the exactly neutral frame is the LAST one, the others deformed."""
    rng = np.random.default_rng(0)
    M = rng.normal(0, 10, (9, 3))
    X = np.repeat(M[None], 6, axis=0) + 0.0
    for f in range(5):
        X[f] += rng.normal(0, 0.5 + 0.3 * f, (9, 3))
    return M, X


@pytest.mark.parametrize("method", ["thesis", "procrustes"])
def test_the_most_neutral_frame_is_chosen_among_the_candidates_only(method):
    M, X = _frames()
    vis = np.ones(X.shape[:2], bool)
    assert most_neutral_frame(X, vis, M, None) == 5
    assert most_neutral_frame(X, vis, M, None, candidates=np.arange(4)) == 0
    nose = np.zeros((6, 3))
    up, lo = np.arange(5), np.arange(4, 9)
    kw = dict(model_nose=np.zeros(3), method=method, reference_frame="auto")
    assert normalize_markers(X, nose, up, lo, M, **kw).reference_frame == 5
    chosen = normalize_markers(X, nose, up, lo, M, reference_candidates=np.arange(4), **kw).reference_frame
    assert chosen in range(4)


def test_training_candidates():
    assert default_test_frames(150) == 10 and default_test_frames(12) == 2
    assert training_candidates(150).tolist() == list(range(140))
    assert training_candidates(12, test_frames=3).tolist() == list(range(9))
    assert training_candidates(12, reference_frames=[4, 2, 2]).tolist() == [2, 4]
    with pytest.raises(ValueError, match=r"reference frames must be frames in \[0, 12\)"):
        training_candidates(12, reference_frames=[12])
    with pytest.raises(ValueError, match="test_frames must be in"):
        training_candidates(12, test_frames=12)
    with pytest.raises(ValueError, match="no candidate frame"):
        most_neutral_frame(np.zeros((3, 4, 3)), np.ones((3, 4), bool), np.zeros((4, 3)), None, candidates=[])
