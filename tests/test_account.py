"""The sighting account (lipgen.recon.account): every (frame, mark) counted once, with reasons."""

import numpy as np

from lipgen.recon.account import account_lines, sighting_account
from lipgen.recon.track import LOST, RECOVERED, TRACKED, Tracks


def _tracks(status, rejected=None):
    status = np.asarray(status, dtype=np.int8)
    uv = np.where((status != LOST)[..., None], 10.0, np.nan) * np.ones(status.shape + (2,))
    return Tracks(uv, status != LOST, status, np.full(status.shape, np.nan),
                  None if rejected is None else np.asarray(rejected, bool))


def test_each_sighting_is_counted_once_with_the_reason_for_marks_never_tracked():
    F, names = 4, ["a", "b", "c", "d", "e"]
    T, L = TRACKED, LOST
    virt = _tracks([[T, T, L, L, L]] * F)
    real_status = np.array([[T, L, L, T, L]] * F)
    real_status[0, 0] = RECOVERED
    rej = np.zeros((F, 5), bool)
    rej[:, 4] = True                                   # e: every real sighting taken back
    real = _tracks(real_status, rej)
    visible = np.zeros((F, 5), bool)
    visible[:, 0] = True
    visible[3, 0] = False                               # a, frame 3: rays too far apart
    gap = np.where(visible, 0.1, np.nan)
    gap[3, 0] = 5.0
    outliers = np.zeros((F, 4), bool)
    outliers[1, 0] = True                               # a, frame 1: a pose outlier
    # layout: c within 1 px of d in the virtual view; everything inside a 100 x 100 view
    expected = np.array([[[10, 10], [30, 10], [50, 50], [51, 50], [70, 70]],
                         [[10, 10], [30, 10], [50, 50], [60, 50], [70, 70]]], float)
    acc = sighting_account((virt, real), visible, gap, 2.0, outliers, names, expected,
                           [(100, 100), (100, 100)], twins=3.0)
    pm = acc["per_mark"]
    for c in pm.values():
        assert c["accepted"] + c["rejected"] + c["unpaired"] + c["lost"] == F
    assert (pm["a"]["accepted"], pm["a"]["rejected"]) == (2, 2)
    assert (pm["b"]["unpaired"], pm["b"]["lost_real"]) == (F, F)
    assert pm["c"]["lost"] == F
    assert (pm["e"]["rejected"], pm["e"]["rejected_real"], pm["e"]["lost_real"]) == (F, F, 0)
    assert sorted(acc["missing"]) == ["b", "c", "d", "e"]
    reasons = {(n["mark"], n["view"]): n["reason"] for n in acc["never_tracked"]}
    assert reasons[("c", "virtual")].startswith("within 1.0 px of d at this resolution")
    assert reasons[("e", "real")] == "all 4 sighting(s) contradicted by the virtual view (rays too far apart)"
    assert reasons[("b", "real")] == "no dot found near where the layout of the other markers puts it"
    assert ("a", "virtual") not in reasons and ("d", "real") not in reasons
    expected[1, 2] = [150, 50]                          # c outside the real view
    acc = sighting_account((virt, real), visible, gap, 2.0, outliers, names, expected,
                           [(100, 100), (100, 100)], twins=3.0)
    assert {(n["mark"], n["view"]): n["reason"] for n in acc["never_tracked"]}[("c", "real")] == \
        "its expected place is outside this view"
    text = "\n".join(account_lines(acc))
    assert "NEVER ACCEPTED" in text and "never tracked in the real view: c: its expected place" in text


def test_a_mark_never_accepted_but_seen_now_and_then_gets_a_reason_too():
    """Seen in a few frames of a view (so not 'never tracked'), yet never accepted: still explained."""
    F, names = 10, ["a", "b"]
    T, L = TRACKED, LOST
    virt = _tracks([[T, T]] * F)
    real_status = np.array([[T, L]] * F)
    real_status[0, 1] = T                              # b: one real sighting in 10, and it is taken back
    rej = np.zeros((F, 2), bool)
    rej[0, 1] = True
    real = _tracks(real_status, rej)
    visible = np.zeros((F, 2), bool)
    visible[:, 0] = True
    gap = np.where(visible, 0.1, np.nan)
    expected = np.array([[[10, 10], [40, 10]], [[10, 10], [40, 10]]], float)
    acc = sighting_account((virt, real), visible, gap, 2.0, np.zeros((F, 1), bool), names, expected,
                           [(100, 100), (100, 100)], twins=3.0)
    assert acc["missing"] == ["b"] and acc["never_tracked"] == []
    (why,) = acc["never_accepted"]
    assert why["mark"] == "b"
    assert why["reason"].startswith("lost in the real view in 9 of 10 frames (")
    assert "the views disagree in 1 frame(s)" in why["reason"]
    assert "seen in one view only in 9 frame(s)" in why["reason"]
    assert "never accepted: b: lost in the real view in 9 of 10" in "\n".join(account_lines(acc))
