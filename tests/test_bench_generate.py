"""The generate bench: the base tree comes from git history, and the per-frame arithmetic."""

import subprocess
from pathlib import Path

import pytest

from lipgen.bench import generate_cpu as g

ROOT = Path(__file__).resolve().parents[1]


def _has_git() -> bool:
    try:
        subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, check=True)
    except (OSError, subprocess.CalledProcessError):
        return False
    return True


@pytest.mark.skipif(not _has_git(), reason="needs this checkout's git history")
def test_base_tree_is_the_commits_package(tmp_path):
    tree = g.base_tree(tmp_path / "base", "HEAD")
    head = subprocess.run(["git", "-C", str(ROOT), "show", "HEAD:lipgen/__init__.py"], capture_output=True,
                          check=True).stdout
    assert (tree / "lipgen" / "__init__.py").read_bytes() == head
    assert g.base_tree(tmp_path / "none", "no-such-commit-xyz") is None


def test_marginal_frames_per_cpu_second_and_ratios(monkeypatch, tmp_path):
    """CPU = start + frames * per_frame: the marginal rate is 1 / per_frame whatever the start-up."""
    cost = {"base": (3.0, 0.2), "new": (5.0, 0.1)}  # (start-up s, s per frame)

    def runs(trees, envs, tmp, tag, frames, workers, together):
        return {n: {"cpu_s": cost[n][0] + frames * cost[n][1], "wall_s": 2.0 * frames} for n in trees}

    monkeypatch.setattr(g, "_runs", runs)
    out = g.generate_cpu({"base": tmp_path, "new": tmp_path}, "base", 1, 8, 48, 2)
    assert out["base"]["frames_per_cpu_s"] == pytest.approx(5.0)
    assert out["new"]["frames_per_cpu_s"] == pytest.approx(10.0)
    assert out["new"]["ratio"] == pytest.approx(2.0)
    assert out["new"]["ratio_rounds"] == pytest.approx([2.0, 2.0])
    assert out["new"]["whole_run_ratio"] == pytest.approx((3.0 + 48 * 0.2) / (5.0 + 48 * 0.1))
    assert out["new"]["frames_per_wall_s"] == pytest.approx(0.5)
    with pytest.raises(ValueError, match="frames_long > frames_short"):
        g.generate_cpu({"base": tmp_path}, "base", 1, 8, 8, 1)


def test_hard_over_new_is_the_per_round_ratio_with_base_cancelled(monkeypatch, tmp_path):
    """Issue 15's figures from one run: hard over the base's default frames, and over today's."""
    per_frame = {"base": [0.2, 0.25], "new": [0.1, 0.125], "hard": [0.4, 0.25]}  # s per frame, per round
    seen_envs = []
    rnd = iter(range(4))

    def runs(trees, envs, tmp, tag, frames, workers, together):
        seen_envs.append(envs)
        r = int(tag.split("-")[0])
        next(rnd)
        return {n: {"cpu_s": 1.0 + frames * per_frame[n][r], "wall_s": 1.0} for n in trees}

    monkeypatch.setattr(g, "_runs", runs)
    envs = {"hard": {"LIPGEN_BENCH_PRESET": "hard"}}
    trees = {"base": tmp_path, "new": tmp_path, "hard": tmp_path}
    out = g.generate_cpu(trees, "base", 1, 8, 48, 2, envs=envs)
    assert all(e == envs for e in seen_envs)
    assert out["hard"]["ratio_rounds"] == pytest.approx([0.5, 1.0])
    h = g.hard_over_new(out)
    assert h["ratio_rounds"] == pytest.approx([0.25, 0.5])
    assert h["ratio"] == pytest.approx(0.375)
