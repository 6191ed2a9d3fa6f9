"""Tracking from the first frame whose markers are all matched (lipgen.recon.anchor): the choice of the
frame, the joining of the backward and forward runs, and the pipeline's use of it."""

import numpy as np
import pytest

from lipgen.recon.anchor import find_anchor, join_runs, track_from_anchor
from lipgen.recon.settings import ReconstructSettings
from lipgen.recon.tracks import Tracks

P = 3


def _tracks(frames, complete=()):
    """Tracks whose uv hold each frame's index (u) and the marker (v); every marker matched at the frames in
    ``complete``, only the first elsewhere. ``frames``: the indices the run was given, in its order."""
    F = len(frames)
    uv = np.zeros((F, P, 2))
    uv[..., 0] = np.asarray(frames, float)[:, None]
    uv[..., 1] = np.arange(P)
    visible = np.zeros((F, P), bool)
    visible[:, 0] = True
    for t, f in enumerate(frames):
        visible[t] = visible[t] | (f in complete)
    return Tracks(uv=uv, visible=visible, status=np.zeros((F, P), np.int8), score=np.full((F, P), 0.5),
                  rejected=np.zeros((F, P), bool))


class FakeTracker:
    """``track(frames, progress)`` over frames that are their own indices; records each run's frames."""

    def __init__(self, complete):
        self.complete, self.runs = set(complete), []

    def __call__(self, frames, progress):
        frames = [int(f) for f in frames]
        self.runs.append(frames)
        for t in range(len(frames)):
            if progress is not None:
                progress(t)
        out = _tracks(frames, self.complete)
        return out, out


def test_the_first_complete_probed_frame_is_the_anchor():
    fake = FakeTracker(complete={7, 10, 12})
    frame, record = find_anchor(lambda i: i, 20, fake, step=5)
    assert frame == 10 and fake.runs == [[0], [5], [10]]
    assert record["probed"] == [0, 5, 10] and record["matched"] == [1, 1, 3] and record["markers"] == P


def test_frame_0_stays_when_complete_or_when_no_frame_is():
    assert find_anchor(lambda i: i, 20, FakeTracker({0, 5}), step=5)[0] == 0
    frame, record = find_anchor(lambda i: i, 12, FakeTracker(set()), step=5)
    assert frame == 0 and record["probed"] == [0, 5, 10]


def test_runs_are_joined_in_time_order_with_each_frame_once():
    fake = FakeTracker(complete={10})
    calls = []
    (virtual, real), record = track_from_anchor(lambda i: i, 14, fake, step=5, progress=calls.append)
    assert record["frame"] == 10
    assert fake.runs[-2:] == [list(range(10, 14)), list(range(10, -1, -1))]   # forward, then backward
    np.testing.assert_array_equal(virtual.uv[:, 0, 0], np.arange(14))
    assert virtual.n_frames == real.n_frames == 14 and virtual.rejected.shape == (14, P)
    assert virtual.visible[10].all() and not virtual.visible[9, 1]
    assert sorted(calls) == list(range(14))                  # the progress of each frame, once


def test_without_a_step_the_tracker_runs_once_from_frame_0():
    fake = FakeTracker(complete={5})
    (virtual, _), record = track_from_anchor(lambda i: i, 8, fake, step=None)
    assert fake.runs == [list(range(8))] and record["frame"] == 0 and record["probed"] == []


def test_join_refuses_runs_of_other_markers():
    a = _tracks([2, 1, 0])
    b = Tracks(uv=np.zeros((3, P + 1, 2)), visible=np.zeros((3, P + 1), bool),
               status=np.zeros((3, P + 1), np.int8), score=np.zeros((3, P + 1)))
    with pytest.raises(ValueError, match="3 and 4 markers"):
        join_runs(a, b)
    joined = join_runs(a, Tracks(uv=a.uv[::-1][2:], visible=a.visible[:1], status=a.status[:1],
                                 score=a.score[:1]))
    assert joined.rejected is None and joined.n_frames == 3


@pytest.mark.parametrize("bad", [0, -5, 2.5, True, "5"])
def test_bad_steps_are_refused(bad):
    with pytest.raises(ValueError, match="anchor"):
        ReconstructSettings(anchor_step=bad)
    with pytest.raises(ValueError, match="anchor step"):
        find_anchor(lambda i: i, 10, FakeTracker(set()), step=bad)


def test_the_cli_passes_the_anchor_step_and_cross_check_and_refuses_a_negative_step(tmp_path, monkeypatch,
                                                                                     capsys):
    import lipgen.recon.pipeline as pipeline
    from lipgen.cli import main

    seen = []

    class Reached(Exception):
        pass

    def capture(dataset, mesh, settings=None, **kwargs):
        seen.append(settings)
        raise Reached

    monkeypatch.setattr(pipeline, "reconstruct_dataset", capture)
    out = ["--out", str(tmp_path / "o.npz")]
    cases = ((["--anchor-step", "0"], None, True), ([], 5, True), (["--anchor-step", "3"], 3, True),
             (["--no-cross-check"], 5, False), (["--no-cross-check", "--anchor-step", "0"], None, False))
    for given, step, check in cases:
        with pytest.raises(Reached):
            main(["reconstruct", str(tmp_path / "ds"), *given, *out])
        assert (seen[-1].anchor_step, seen[-1].cross_check) == (step, check)
        assert seen[-1].tracker == ReconstructSettings().tracker and seen[-1].cross_check_fill   # as default
    for bad in ("-1", "two"):
        with pytest.raises(SystemExit):
            main(["reconstruct", str(tmp_path / "ds"), "--anchor-step", bad, *out])
        err = capsys.readouterr().err
        assert "--anchor-step" in err and repr(bad) in err
    assert not (tmp_path / "o.npz").exists()


def test_the_start_is_said_only_when_it_is_not_frame_0():
    from lipgen.recon.anchor import anchor_line

    assert anchor_line(None) is None and anchor_line({}) is None            # made before anchors
    assert anchor_line({"frame": 0, "matched": [17], "markers": 17}) is None
    line = anchor_line({"frame": 10, "matched": [13, 15, 17], "markers": 17})
    assert line.startswith("Tracking started at frame 10") and "frame 0: 13 of 17" in line
