"""Interleaved ratio timing and the start-up suite's import-time parser (issue 22)."""

from __future__ import annotations

import time

import pytest

from lipgen.bench.compare import interleaved
from lipgen.bench.startup import import_seconds


def test_interleaved_ratios():
    calls = []
    fns = {"base": lambda: calls.append("base"), "slow": lambda: (calls.append("slow"), time.sleep(0.002))}
    out = interleaved(fns, "base", rounds=3, warmup=False)
    assert calls == ["base", "slow"] * 3  # one of each per round, in turn
    assert out["base"]["ratio_median"] == 1.0
    assert out["slow"]["ratio_median"] > 1.0 and out["slow"]["best_s"] >= 0.002


def test_interleaved_rejects_bad_arguments():
    with pytest.raises(ValueError, match="baseline 'x'"):
        interleaved({"a": lambda: None}, "x")
    with pytest.raises(ValueError, match="rounds must be at least 1"):
        interleaved({"a": lambda: None}, "a", rounds=0)


def test_import_seconds_counts_top_level_imports():
    # the interpreter's own start-up imports (encodings, site, ...) are counted, so never 0
    assert import_seconds(["-c", "pass"]) > 0
    assert import_seconds(["-c", "import json, argparse, logging"]) > 0
