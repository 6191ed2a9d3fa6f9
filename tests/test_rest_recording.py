"""The subject's rest from a recording: the frames nearest the model's rest (lipgen.recon.rest)."""

import numpy as np
import pytest

from lipgen.recon.rest import recording_rest, rest_frames_near


def _speech(F=150, P=16, seed=0, rest=None):
    """Markers that rest (plus noise) in pauses and move through random syllable targets between."""
    rng = np.random.default_rng(seed)
    rest = rng.normal(0, 10, (P, 3)) if rest is None else rest
    dirs = rng.normal(0, 3, (4, P, 3))
    act = np.zeros((F + 40, 4))
    t = 0
    while t < F:
        n = rng.integers(15, 30)  # a phrase of moving syllables, then a pause of 8 frames
        phase = np.arange(n)
        act[t:t + n] = np.abs(np.sin(np.pi * phase / 6.0))[:, None] * rng.uniform(0.5, 1.5, 4)
        t += n + 8
    X = rest + np.einsum("fa,apk->fpk", act[:F], dirs)
    return X, rest, act[:F]


def _model():
    from lipgen.mesh.procedural import lip_mesh

    mesh = lip_mesh(0)
    return mesh, mesh.vertices[mesh.markers]


def _shape(M, rms, seed):
    """A subject's own shape: a random shift per marker of ``rms`` mm RMS."""
    return np.random.default_rng(seed).normal(0, rms / np.sqrt(3), M.shape)


def test_rest_frames_are_pause_frames_and_rest_is_recovered():
    _, M = _model()
    X, rest, act = _speech(rest=M + _shape(M, 2.0, 5))
    noisy = X + np.random.default_rng(1).normal(0, 0.05, X.shape)
    vis = np.ones(X.shape[:2], bool)
    q = rest_frames_near(noisy, vis, M)
    assert len(q) == 11 and np.all(act[q].max(1) < 0.3)
    est = recording_rest(noisy, vis, M)
    assert np.sqrt(np.mean(np.sum((est - rest) ** 2, 1))) < 0.1
    # the median of all frames is pulled by the motion
    assert np.sqrt(np.mean(np.sum((np.median(noisy, 0) - rest) ** 2, 1))) > 1.0


def test_a_held_posture_that_recurs_more_often_than_the_rest_is_not_taken():
    """A clip with one pause and a vowel held four times, each held longer and stiller than the
    pause (subject seed 27 of table51-pipeline): the densest cluster of still frames is the vowel,
    6 mm from rest; the frames nearest the model's rest (2.5 mm from the subject's) are the pause."""
    _, M = _model()
    rest = M + _shape(M, 2.5, 7)
    vowel = np.random.default_rng(8).normal(0, 6 / np.sqrt(3), M.shape)
    F = 150
    rng = np.random.default_rng(9)
    X = rest + rng.uniform(1, 2, (F, 1, 1)) * rng.normal(0, 3, (F, *M.shape))  # moving
    for start in (10, 40, 70, 120):  # held vowel, 10 frames, very still
        X[start:start + 10] = rest + vowel + rng.normal(0, 0.02, (10, *M.shape))
    X[100:108] = rest + rng.normal(0, 0.2, (8, *M.shape))  # one pause, less still
    vis = np.ones((F, len(M)), bool)
    q = rest_frames_near(X, vis, M)
    assert set(q) >= set(range(100, 108))
    est = recording_rest(X, vis, M)
    assert np.sqrt(np.mean(np.sum((est - rest) ** 2, 1))) < 0.3


def test_unmeasured_marker_is_nan_and_bad_input_refused():
    _, M = _model()
    X, rest, _ = _speech(rest=M)
    vis = np.ones(X.shape[:2], bool)
    vis[:, 3] = False
    est = recording_rest(X, vis, M)
    assert np.isnan(est[3]).all() and np.isfinite(np.delete(est, 3, 0)).all()
    with pytest.raises(ValueError, match="share"):
        rest_frames_near(X, vis, M, share=0.0)
    with pytest.raises(ValueError, match="measured must have shape"):
        rest_frames_near(X, vis[:, :5], M)
    with pytest.raises(ValueError, match=r"start.*\(16, 3\)"):
        rest_frames_near(X, vis, M[:5])
    with pytest.raises(ValueError, match="at least 5 frames"):
        rest_frames_near(X[:4], vis[:4], M)
    with pytest.raises(ValueError, match="min_sightings"):
        recording_rest(X, vis, M, min_sightings=1.5)
    with pytest.raises(ValueError, match="names must name the 16"):
        recording_rest(X, vis, M, names=["a"])


def test_a_frame_with_fewer_than_3_markers_measured_is_never_a_rest_frame():
    _, M = _model()
    X, _, _ = _speech(rest=M)
    X = X + np.random.default_rng(2).normal(0, 0.05, X.shape)
    vis = np.ones(X.shape[:2], bool)
    X[60] = M  # exactly the model's rest, but only 2 markers seen
    vis[60, 2:] = False
    assert 60 not in rest_frames_near(X, vis, M)
    vis[60, 2] = True
    assert 60 in rest_frames_near(X, vis, M)


def test_rest_of_a_subject_shaped_unlike_the_model_is_recovered():
    """The subject's rest differs from the model's by a known shift per marker (1.5 mm RMS): the
    recording's rest recovers it, so the displacements lose the constant offset that measuring
    them from the model's rest gives."""
    _, M = _model()
    shift = _shape(M, 1.5, 3)
    X, rest, _ = _speech(rest=M + shift)
    noisy = X + np.random.default_rng(4).normal(0, 0.05, X.shape)
    vis = np.ones(X.shape[:2], bool)
    est = recording_rest(noisy, vis, M)
    assert np.sqrt(np.mean(np.sum((est - (M + shift)) ** 2, axis=1))) < 0.1
    true = X - rest  # the subject's own displacements
    offset_model = np.mean((noisy - M) - true, axis=0)  # per marker, constant over the frames
    offset_est = np.mean((noisy - est) - true, axis=0)
    assert np.allclose(offset_model, shift, atol=0.02)
    assert np.sqrt(np.mean(np.sum(offset_est**2, axis=1))) < 0.1 < 0.5 < np.sqrt(np.mean(np.sum(shift**2, 1)))


def test_a_marker_never_measured_at_rest_falls_back_and_is_named(caplog):
    """A marker seen only while the lips move (e.g. hidden in every pause) has no rest of its own:
    its row is NaN, a warning names it, and the renormalisation measures it from the model's rest."""
    import logging

    mesh, M = _model()
    X, rest, act = _speech(rest=M + 1.0)
    vis = np.ones(X.shape[:2], bool)
    vis[:, 5] = act.max(axis=1) > 0.5  # marker 5 is seen only in motion
    with caplog.at_level(logging.WARNING, logger="lipgen.recon.rest"):
        est = recording_rest(X, vis, M, names=mesh.marker_names)
    assert np.isnan(est[5]).all() and np.isfinite(np.delete(est, 5, 0)).all()
    assert mesh.marker_names[5] in caplog.text and "model's rest" in caplog.text
    assert np.allclose(np.delete(est, 5, 0), np.delete(M + 1.0, 5, 0), atol=1e-9)
    from lipgen.recon.rereference import _rest_markers

    used = _rest_markers(est, X, vis, M)
    assert np.array_equal(used[5], M[5])


def test_a_short_recording_takes_at_least_half_of_min_frames():
    """40 frames: 15 % would be 6 frames (3 rest frames); MIN_REST_FRAMES keeps 5 rest frames."""
    _, M = _model()
    X, _, _ = _speech(F=40, rest=M)
    vis = np.ones(X.shape[:2], bool)
    assert len(rest_frames_near(X, vis, M)) == 5
    assert len(rest_frames_near(X, vis, M, min_frames=0)) == 3
