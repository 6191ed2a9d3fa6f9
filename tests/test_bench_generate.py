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


def _fake_runs(cost):
    """``_runs`` whose calls cost ``start + frames * per_frame`` CPU s (``cost[name][round]``), and
    a one-off ``first`` s in each process's first call (the warm-up's)."""
    seen = []

    def runs(trees, envs, tmp, tag, counts, workers):
        r = int(tag)
        seen.append((list(trees), envs, counts))
        out = {}
        for n in trees:
            start, per_frame, first = cost[n][r]
            out[n] = [{"frames": f, "cpu_s": start + f * per_frame + (first if k == 0 else 0.0),
                       "wall_s": 2.0 * f} for k, f in enumerate(counts)]
        return out

    return runs, seen


def test_marginal_frames_per_cpu_second_and_ratios(monkeypatch, tmp_path):
    """CPU = start + frames * per_frame: the marginal rate is 1 / per_frame whatever the start-up,
    and the warm-up call's one-off costs do not enter it."""
    cost = {"base": [(3.0, 0.2, 4.0)] * 2, "new": [(5.0, 0.1, 9.0)] * 2}  # (start s, s per frame, one-off s)
    runs, seen = _fake_runs(cost)
    monkeypatch.setattr(g, "_runs", runs)
    out = g.generate_cpu({"base": tmp_path, "new": tmp_path}, "base", 1, 8, 48, 2)
    assert [s[2] for s in seen] == [[8, 8, 48]] * 2  # warm-up, short, long
    assert [s[0] for s in seen] == [["base", "new"], ["new", "base"]]  # the order alternates
    assert out["base"]["frames_per_cpu_s"] == pytest.approx(5.0)
    assert out["new"]["frames_per_cpu_s"] == pytest.approx(10.0)
    assert out["new"]["ratio"] == pytest.approx(2.0)
    assert out["new"]["ratio_spread"]["rounds"] == pytest.approx([2.0, 2.0])
    assert out["new"]["whole_call_ratio"] == pytest.approx((3.0 + 48 * 0.2) / (5.0 + 48 * 0.1))
    assert out["new"]["frames_per_wall_s"] == pytest.approx(0.5)
    with pytest.raises(ValueError, match="frames_long > frames_short"):
        g.generate_cpu({"base": tmp_path}, "base", 1, 8, 8, 1)
    with pytest.raises(ValueError, match="baseline 'old'"):
        g.generate_cpu({"base": tmp_path}, "old", 1, 8, 48, 1)
    with pytest.raises(ValueError, match="rounds"):
        g.generate_cpu({"base": tmp_path}, "base", 1, 8, 48, 0)


def test_ratios_are_per_round_then_the_median(monkeypatch, tmp_path):
    """A round where both trees are slowed by the same factor gives the same ratio: the median is
    of per-round ratios, not a ratio of medians."""
    slow = [1.0, 3.0, 1.5]
    cost = {"base": [(1.0, 0.2 * f, 0.0) for f in slow],
            "new": [(1.0, 0.1 * f * (1.2 if r == 2 else 1.0), 0.0) for r, f in enumerate(slow)]}
    runs, _ = _fake_runs(cost)
    monkeypatch.setattr(g, "_runs", runs)
    out = g.generate_cpu({"base": tmp_path, "new": tmp_path}, "base", 1, 8, 48, 3, warmup=False)
    assert out["new"]["ratio_spread"]["rounds"] == pytest.approx([2.0, 2.0, 2.0 / 1.2])
    assert out["new"]["ratio"] == pytest.approx(2.0)
    assert out["new"]["ratio_spread"]["range"] == pytest.approx([2.0 / 1.2, 2.0])


def test_spread():
    s = g.spread([1.0, 2.0, 3.0, 4.0, 5.0])
    assert s["median"] == 3.0 and s["quartiles"] == [2.0, 4.0] and s["range"] == [1.0, 5.0]


def test_a_run_refuses_a_lipgen_other_than_its_trees(tmp_path, monkeypatch):
    """Started from a checkout's root, ``python -c`` would import that checkout's lipgen whatever
    PYTHONPATH says; each run checks that it imported its own tree's package."""
    monkeypatch.chdir(ROOT)
    empty = tmp_path / "no-lipgen-here"
    empty.mkdir()
    proc = g._start(empty, tmp_path / "out", [1, 2], 1, None)
    with pytest.raises(RuntimeError, match="not the lipgen of"):
        g._finish(proc, empty)


def test_ratios_against_a_second_baseline_are_per_round(monkeypatch, tmp_path):
    """``_over`` divides per-round rates of the same run: 10 / 4 frames per CPU second and 10 / 5
    per wall second in every round."""
    cost = {"base": [(1.0, 0.2, 0.0)] * 3, "one": [(1.0, 0.25, 0.0)] * 3, "new": [(1.0, 0.1, 0.0)] * 3}
    runs, _ = _fake_runs(cost)
    monkeypatch.setattr(g, "_runs", runs)
    out = g.generate_cpu({"base": tmp_path, "one": tmp_path, "new": tmp_path}, "base", 1, 8, 48, 3)
    over = g._over(out, "new", "one")
    assert over["ratio"] == pytest.approx(2.5)
    assert over["ratio_spread"]["rounds"] == pytest.approx([2.5] * 3)
    assert over["wall_ratio"] == pytest.approx(1.0)  # the fake's wall is 2 s per frame in every tree


def test_the_suite_times_hard_frames_with_and_without_their_truth_physics(monkeypatch, tmp_path):
    """``hard`` runs with the linear truth (the frame pipeline), ``hard_layer`` with the hard
    preset's own tissue layer (what a user waits for), in the same rounds."""
    per_frame = {"base": 0.1, "base_one_thread": 0.1, "new": 0.05, "hard": 0.15, "hard_layer": 0.3}
    runs, seen = _fake_runs({n: [(1.0, c, 0.0)] for n, c in per_frame.items()})
    monkeypatch.setattr(g, "_runs", runs)
    monkeypatch.setattr(g, "base_tree", lambda dest, commit=g.BASE_COMMIT: tmp_path)
    out = g.run(quick=True)
    trees, envs, _ = seen[-1]
    assert set(trees) == {"base", "base_one_thread", "hard", "hard_layer"}
    assert envs["hard_layer"]["LIPGEN_BENCH_PHYSICS"] == "layer"
    assert "LIPGEN_BENCH_PHYSICS" not in envs["hard"]
    assert 'os.environ.get("LIPGEN_BENCH_PHYSICS", "linear")' in g._DRIVER
    assert out["hard_over_base_one_thread"]["ratio"] == pytest.approx(0.1 / 0.15)
    assert out["hard_layer_over_base_one_thread"]["ratio"] == pytest.approx(0.1 / 0.3)
