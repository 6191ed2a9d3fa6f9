"""Frame-to-frame prediction (lipgen.recon.association.predict): global jumps and clutter."""

import numpy as np

from lipgen.recon.association import predict
from lipgen.recon.pointreg import register_points


def _layout(rng, n=10):
    # a lip-like ring of markers, about 12 px apart
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([160 + 40 * np.cos(a), 240 + 18 * np.sin(a)]) + rng.normal(0, 1.0, (n, 2))


def test_a_clutter_copy_of_part_of_the_layout_does_not_move_the_prediction():
    # Half the markers hidden; the face did not move, but clutter (teeth, nostrils) 30 px away
    # repeats 7 markers' layout. The old rule (half the markers explained) followed it.
    for seed in range(5):
        rng = np.random.default_rng(seed)
        pred = _layout(rng)
        seen = np.arange(0, 10, 2)
        lure = pred[:7] + [30.0, 4.0] + rng.normal(0, 0.2, (7, 2))
        dots = np.vstack([pred[seen] + rng.normal(0, 0.3, (5, 2)), lure])
        match, aligned = register_points(dots, pred, 8.0)
        assert (match >= 0).sum() >= 5 and np.median(np.linalg.norm(aligned - pred, axis=1)) > 20  # the lure
        out = predict(pred, np.zeros_like(pred), np.zeros(10, int), None, dots, 8.0)
        assert np.abs(out - pred).max() < 8.0


def test_a_whole_face_jump_is_still_followed():
    for seed in range(5):
        rng = np.random.default_rng(seed)
        pred = _layout(rng)
        shift = np.array([25.0, -12.0])
        dots = np.vstack([pred[1:] + shift + rng.normal(0, 0.2, (9, 2)), [[60.0, 60.0]]])   # one hidden
        out = predict(pred, np.zeros_like(pred), np.zeros(10, int), None, dots, 8.0)
        assert np.abs(out - (pred + shift)).max() < 1.5
