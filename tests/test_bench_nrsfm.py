"""Bench suite ``nrsfm``: the short-sequence missing-points case (K = auto on a validation body)."""

import numpy as np


def test_the_body_case_times_k_auto_against_the_body_complete(monkeypatch):
    from lipgen.bench import nrsfm as bench
    from lipgen.nrsfm.validation import human_sequence

    calls = []

    def fake(W, S, rounds, k=12):
        calls.append((W, S, rounds, k))
        return {"k": k, "timing": {}, "e3d": {}, "k_used": {}}

    monkeypatch.setattr(bench, "_missing", fake)
    out = bench._missing_body(rounds=1)
    body = human_sequence(bench.BODY_SEED, 80)
    (W, S, rounds, k), = calls
    assert np.array_equal(W, body.W) and np.array_equal(S, body.S) and rounds == 1 and k == "auto"
    assert out["sequence"] == body.name and out["frames"] == 80 and out["points"] == body.W.shape[1]
    assert out["k"] == "auto"
