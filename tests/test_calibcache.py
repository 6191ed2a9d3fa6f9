"""The per-process calibration cache: a calibration is reused only for the very same inputs.

The calibration itself is replaced by a counter here (the cache's keying is what is tested); that a
reused calibration gives the same reconstruction is checked on rendered data by
``tests/test_recording.py`` (a folder of frames and a video, each calibrated by ``recording init``
and then reused by ``reconstruct``, against the dataset's own run) and ``tests/test_e2e.py``.
"""

from dataclasses import replace

import numpy as np
import pytest

from lipgen.recon import calibcache
from lipgen.rig.camera import default_rig
from lipgen.rig.target import Chessboard


@pytest.fixture
def calls(monkeypatch):
    """Each real calibration appends its inputs; it returns a fresh, mutable result."""
    made = []

    def count(frames, layout, board, **options):
        made.append((len(frames), layout.split, board, options))
        return {"call": len(made), "rms": {"all": 0.1}}

    monkeypatch.setattr(calibcache, "calibrate_rig", count)
    monkeypatch.setattr(calibcache, "_CACHE", type(calibcache._CACHE)())
    monkeypatch.delenv(calibcache.CACHE_ENV, raising=False)
    return made


def _frames(seed=0, n=4):
    rng = np.random.default_rng(seed)
    return [rng.integers(0, 255, (48, 64, 3), dtype=np.uint8) for _ in range(n)]


def test_the_same_inputs_are_calibrated_once_and_each_caller_gets_its_own_copy(calls):
    rig, board = default_rig(64, 48), Chessboard(9, 6, 8.0)
    first = calibcache.calibrated(_frames(), rig, board)
    first["rms"]["all"] = 99.0  # a caller changing its result changes no one else's
    again = calibcache.calibrated([f.copy() for f in _frames()], rig, [board] * 4)  # the same boards, listed
    assert len(calls) == 1 and again == {"call": 1, "rms": {"all": 0.1}}
    assert again is not calibcache.calibrated(_frames(), rig, board)


def test_any_changed_input_is_calibrated_again(calls):
    rig, board = default_rig(64, 48), Chessboard(9, 6, 8.0)
    calibcache.calibrated(_frames(), rig, board)
    # another mirror with the same size, side and split is the same layout (its cameras are never read)
    other_mirror = replace(rig, mirror_offset=rig.mirror_offset + 20.0)
    assert calibcache.calibrated(_frames(), other_mirror, board)["call"] == 1
    one_pixel = _frames()
    one_pixel[2][10, 20, 1] ^= 1
    changed = [
        (one_pixel, rig, board, {}),
        (_frames()[:3], rig, board, {}),
        ([f.astype(np.uint16) for f in _frames()], rig, board, {}),  # same values, another dtype
        (_frames(), replace(rig, split=30), board, {}),
        (_frames(), replace(rig, mirror_side="right"), board, {}),
        (_frames(), rig, Chessboard(9, 6, 7.0), {}),
        (_frames(), rig, board, {"distortion": "full"}),
        (_frames(), rig, board, {"reference": 1}),
    ]
    for k, (frames, layout, b, options) in enumerate(changed):
        assert calibcache.calibrated(frames, layout, b, **options)["call"] == k + 2, k
    assert len(calls) == 1 + len(changed)


def test_the_oldest_is_forgotten_and_the_cache_can_be_turned_off(calls, monkeypatch):
    rig, board = default_rig(64, 48), Chessboard(9, 6, 8.0)
    for seed in range(calibcache.CACHE_SIZE + 1):
        calibcache.calibrated(_frames(seed), rig, board)
    assert (
        calibcache.calibrated(_frames(calibcache.CACHE_SIZE), rig, board)["call"] == calibcache.CACHE_SIZE + 1
    )
    assert calibcache.calibrated(_frames(0), rig, board)["call"] == calibcache.CACHE_SIZE + 2  # forgotten
    monkeypatch.setenv(calibcache.CACHE_ENV, "off")
    n = len(calls)
    calibcache.calibrated(_frames(0), rig, board)
    calibcache.calibrated(_frames(0), rig, board)
    assert len(calls) == n + 2
