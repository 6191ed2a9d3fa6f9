"""The subject's rest from the quiet frames of a recording (lipgen.recon.rest)."""

import numpy as np
import pytest

from lipgen.recon.rest import quiet_frames, quiet_rest


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


def test_quiet_frames_are_pause_frames_and_rest_is_recovered():
    X, rest, act = _speech()
    noisy = X + np.random.default_rng(1).normal(0, 0.05, X.shape)
    vis = np.ones(X.shape[:2], bool)
    q = quiet_frames(noisy, vis, share=0.15)
    assert 0 < np.mean(act[q].max(1) > 0.3) < 0.5  # held targets are quiet too, pauses more often
    est = quiet_rest(noisy, vis, share=0.15)
    assert np.sqrt(np.mean((est - rest) ** 2)) < 0.1
    # the median of all frames is pulled by the motion
    assert np.sqrt(np.mean((np.median(noisy, 0) - rest) ** 2)) > 1.0


def test_quiet_rest_unmeasured_marker_is_nan_and_bad_share_refused():
    X, rest, _ = _speech()
    vis = np.ones(X.shape[:2], bool)
    vis[:, 3] = False
    est = quiet_rest(X, vis)
    assert np.isnan(est[3]).all() and np.isfinite(np.delete(est, 3, 0)).all()
    with pytest.raises(ValueError, match="share"):
        quiet_frames(X, vis, share=0.0)
    with pytest.raises(ValueError, match="measured must have shape"):
        quiet_frames(X, vis[:, :5])
    with pytest.raises(ValueError, match="min_sightings"):
        quiet_rest(X, vis, min_sightings=1.5)
    with pytest.raises(ValueError, match="names must name the 16"):
        quiet_rest(X, vis, names=["a"])


def _model():
    from lipgen.mesh.procedural import lip_mesh

    mesh = lip_mesh(0)
    return mesh, mesh.vertices[mesh.markers]


def test_rest_of_a_subject_shaped_unlike_the_model_is_recovered():
    """The subject's rest differs from the model's by a known shift per marker (1.5 mm RMS): the rest
    from the quiet frames recovers it, so the displacements lose the constant offset that measuring
    them from the model's rest gives."""
    _, M = _model()
    shift = np.random.default_rng(3).normal(0, 1.5 / np.sqrt(3), M.shape)
    X, rest, _ = _speech(rest=M + shift)
    noisy = X + np.random.default_rng(4).normal(0, 0.05, X.shape)
    vis = np.ones(X.shape[:2], bool)
    est = quiet_rest(noisy, vis)
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
        est = quiet_rest(X, vis, names=mesh.marker_names)
    assert np.isnan(est[5]).all() and np.isfinite(np.delete(est, 5, 0)).all()
    assert mesh.marker_names[5] in caplog.text and "model's rest" in caplog.text
    assert np.allclose(np.delete(est, 5, 0), np.delete(M + 1.0, 5, 0), atol=1e-9)
    from lipgen.recon.rereference import _rest_markers

    used = _rest_markers(est, X, vis, M)
    assert np.array_equal(used[5], M[5])


def test_a_short_recording_takes_at_least_min_frames_quiet_frames():
    """40 frames: 15 % would be 6 quiet frames (3 rest frames); min_frames keeps 10 (5 rest frames)."""
    from lipgen.recon.rest import _densest_half

    X, _, _ = _speech(F=40)
    vis = np.ones(X.shape[:2], bool)
    assert len(quiet_frames(X, vis, 0.15)) == 6
    assert len(_densest_half(X, vis, quiet_frames(X, vis, 10 / 40))) == 5
