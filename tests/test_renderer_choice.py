"""Choosing the renderer: settings, manifest, campaign plan keys and bad input (no rendering here)."""

from __future__ import annotations

import contextlib
import importlib.abc
import sys

import pytest

from lipgen.dataset.settings import GenerateSettings
from lipgen.errors import MissingDependencyError


class _NoModule(importlib.abc.MetaPathFinder):
    """Makes ``import NAME`` fail as it does where NAME is not installed."""

    def __init__(self, name: str) -> None:
        self.name = name

    def find_spec(self, fullname, path, target=None):
        if fullname == self.name or fullname.startswith(self.name + "."):
            raise ModuleNotFoundError(f"No module named {fullname!r}", name=fullname)
        return None


@contextlib.contextmanager
def without_module(name: str):
    """``name`` (and its submodules) cannot be imported inside the block."""
    saved = {k: sys.modules.pop(k) for k in list(sys.modules) if k == name or k.startswith(name + ".")}
    finder = _NoModule(name)
    sys.meta_path.insert(0, finder)
    try:
        yield
    finally:
        sys.meta_path.remove(finder)
        sys.modules.update(saved)


def test_the_renderer_is_recorded_and_pyrender_manifests_are_unchanged():
    plain = GenerateSettings(frames=2, size=(160, 120)).to_dict()
    assert "renderer" not in plain and "cycles_samples" not in plain  # as before the choice existed
    s = GenerateSettings(frames=2, size=(160, 120), renderer="cycles", cycles_samples=32)
    d = s.to_dict()
    assert d["renderer"] == "cycles" and d["cycles_samples"] == 32
    assert GenerateSettings.from_dict(d) == s
    assert GenerateSettings.from_dict(plain).renderer == "pyrender"


@pytest.mark.parametrize("kw, match", [
    ({"renderer": "mitsuba"}, r"unknown renderer 'mitsuba'; choose one of \('pyrender', 'cycles'\)"),
    ({"cycles_samples": 0}, r"cycles_samples must be a whole number in \[1, 4096\], got 0"),
])
def test_bad_renderer_settings_are_refused(kw, match):
    with pytest.raises(ValueError, match=match):
        GenerateSettings(frames=2, size=(160, 120), **kw)


def test_the_renderer_is_a_campaign_plan_key():
    from lipgen.campaign.plan import PlanError, parse_plan

    base = {"frames": 2, "size": "160x120", "calib_frames": 0}
    only = {"stages": ["generate"]}
    plan = parse_plan({"base": base, "grid": {"renderer": ["pyrender", "cycles"]}, "campaign": only})
    assert [it.settings.renderer for it in plan.items] == ["pyrender", "cycles"]
    with pytest.raises(PlanError, match="unknown renderer 'eevee'"):
        parse_plan({"base": {**base, "renderer": "eevee"}, "campaign": only})


def test_cycles_without_bpy_is_refused_before_anything_is_written(tmp_path):
    from lipgen.dataset.generate import generate

    out = tmp_path / "ds"
    s = GenerateSettings(frames=1, calib_frames=0, size=(160, 120), renderer="cycles")
    fix = r"pip install 'lipgen\[blender\]'"
    with without_module("bpy"), pytest.raises(MissingDependencyError, match=fix):
        generate(out, s, progress=False)
    assert not out.exists()


def test_the_cli_takes_the_renderer(tmp_path, capsys):
    from lipgen.cli import main

    with pytest.raises(SystemExit):
        main(["generate", "--out", str(tmp_path / "x"), "--renderer", "povray"])
    assert "invalid choice: 'povray'" in capsys.readouterr().err
    with without_module("bpy"):
        code = main(["generate", "--out", str(tmp_path / "x"), "--renderer", "cycles", "--frames", "1",
                     "--size", "160x120", "--no-progress"])
    assert code != 0 and "lipgen[blender]" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
