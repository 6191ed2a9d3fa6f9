"""Whether the tracks determine the rotations (lipgen.nrsfm.support): the halves' disagreement, the flat
fallback of k="auto", and its determinism."""

import numpy as np
import pytest

from lipgen._rotation import rotation_matrix
from lipgen._threads import blas_threads
from lipgen.nrsfm import reconstruct
from lipgen.nrsfm.kchoice import reconstruct_auto
from lipgen.nrsfm.support import (
    SUPPORT_DEG,
    depth_support,
    flat_answer,
    rotation_disagreement,
    rotation_stability,
)
from lipgen.nrsfm.synthetic import articulated_sequence, random_rotations
from lipgen.nrsfm.validation import human_sequence


def _same(a, b):
    return all(np.array_equal(getattr(a, n), getattr(b, n)) for n in ("rotations", "weights", "basis",
                                                                       "translation"))


def test_disagreement_is_zero_up_to_the_gauge_and_the_per_frame_signs():
    rng = np.random.default_rng(0)
    B = random_rotations(30, rng)
    Q = rotation_matrix([0.4, -1.1, 2.0]) @ np.diag([1.0, 1.0, -1.0])     # a reflection of the object frame
    sign = np.where(rng.random(30) < 0.5, -1.0, 1.0)
    A = sign[:, None, None] * (B[:, :2] @ Q.T)            # A_f Q = s_f B_f: the same rotations
    assert rotation_disagreement(A, B).max() < 1e-6


def test_disagreement_of_a_camera_turn_is_its_angle():
    """``A_f = T B_f`` with T a turn of the camera frame about its z axis by a: no transform of the
    object frame undoes it when the views differ, so each frame disagrees by about a."""
    rng = np.random.default_rng(1)
    B = random_rotations(60, rng)
    T = rotation_matrix([0.0, 0.0, np.radians(10.0)])
    angles = rotation_disagreement(T @ B, B)
    assert np.median(angles) == pytest.approx(10.0, abs=2.0)
    with pytest.raises(ValueError, match="shapes"):
        rotation_disagreement(B[:5], B[:6])


def test_a_determined_body_agrees_and_keeps_its_reconstruction_bit_for_bit():
    """Development body 1100 (5 degrees per frame, 40 frames): the halves agree to a fraction of a
    degree, and k="auto" returns the consensus answer itself, flagged as supported."""
    s = human_sequence(1100, 40)
    angle, record = rotation_stability(s.W, 4)
    assert angle < 0.5 * SUPPORT_DEG and record["k"] == 4
    rec = reconstruct_auto(s.W, "dai", kmax=6)
    ref = reconstruct_auto(s.W, "dai", kmax=6, support=None)
    assert _same(rec, ref) and rec.depth_supported and rec.info["depth_support"]["tested"]
    assert "depth_support" not in ref.info and ref.depth_supported


def test_undetermined_rotations_are_flagged_and_answered_flat():
    """Tracks of no rigid or low-rank motion at all (independent random points in every frame): no
    rotation explains them, the halves' corrective triples land anywhere, and k="auto" returns the
    flat answer: the same image, zero depth, flagged."""
    W = np.random.default_rng(0).standard_normal((60, 16))
    supported, record = depth_support(W, 2)
    assert not supported and record["tested"] and record["angle_deg"] > 10 * SUPPORT_DEG
    rec = reconstruct(W, "auto")
    assert not rec.depth_supported and rec.info["depth_factor"] == 0.0
    assert np.abs(rec.shapes[:, 2]).max() < 1e-9 * np.abs(rec.shapes).max()
    ref = reconstruct_auto(W, "dai", support=None)
    assert np.allclose(rec.reproject(), ref.reproject(), atol=1e-9)
    assert "disagree" in rec.info["depth_support"]["reason"]


def test_a_slowly_turning_dancer_is_flagged():
    """Development body 1106 (dance, 80 frames), where the rotations of dai were 31 degrees from the
    truth and its answer no better than flat: the halves disagree by tens of degrees at its K."""
    s = human_sequence(1106, 80)
    supported, record = depth_support(s.W, 4)
    assert not supported and record["angle_deg"] > 20


def test_flat_answer_keeps_the_image():
    W, _, _ = articulated_sequence(30, np.random.default_rng(2), n_bones=5, markers_per_bone=3)
    rec = reconstruct(W, 3)
    flat = flat_answer(rec, {"supported": False, "reason": "test"})
    assert np.allclose(flat.reproject(), rec.reproject(), atol=1e-9)
    assert np.abs(flat.shapes[:, 2]).max() < 1e-9 and not flat.depth_supported
    assert np.array_equal(flat.rotations, rec.rotations)


def test_short_sequences_are_not_tested_and_bad_thresholds_refused():
    W, _, _ = articulated_sequence(12, np.random.default_rng(3), n_bones=4, markers_per_bone=3)
    supported, record = depth_support(W, 2)
    assert supported and not record["tested"] and "not tested" in record["reason"]
    for bad in (-1.0, 180.0, "2", True):
        with pytest.raises(ValueError, match="threshold"):
            depth_support(W, 2, threshold=bad)


def test_the_same_bytes_with_one_or_two_blas_threads():
    s = human_sequence(1102, 40)
    with blas_threads(1):
        one = rotation_stability(s.W, 5)
    with blas_threads(2):
        two = rotation_stability(s.W, 5)
    assert one[0] == two[0] and one[1] == two[1]
