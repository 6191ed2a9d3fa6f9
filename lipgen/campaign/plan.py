"""A campaign plan: many datasets (a grid and/or a list of generate settings) and the stages
to run on each, read from TOML and checked whole before anything runs.

A plan (every table optional but ``[base]`` or ``[grid]`` or ``[[items]]`` must give at least
one item)::

    [campaign]
    stages = ["generate", "reconstruct", "train", "evaluate", "nrsfm"]   # default: all
    chunk_frames = 16        # frames per generate task (one long dataset spreads too)
    retries = 2              # re-runs of a task whose worker died

    [base]                   # generate settings shared by every item
    frames = 60
    size = [320, 240]        # or "320x240"

    [grid]                   # every combination of these lists ...
    seed = [0, 1, 2]
    noise = [0.5, 2.0]

    [[items]]                # ... crossed with each of these (default: one empty item)
    script = "AA:0.3 EE OO"

    [reconstruct]            # normalisation, mesh
    [train]                  # modes, test_frames
    [nrsfm]                  # view, k, method

The generate keys are the fields of :class:`lipgen.dataset.GenerateSettings`, whatever they are
in this lipgen (a field added there is a plan key here); each item's settings are built and
checked by that class, and an error names the item and the key.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path

from lipgen.dataset.layout import GenerateSettings
from lipgen.errors import LipgenError

__all__ = ["PlanError", "CampaignPlan", "CampaignItem", "STAGES", "load_plan", "parse_plan"]

STAGES = ("generate", "reconstruct", "train", "evaluate", "nrsfm")
"""The stages a plan may name, in pipeline order."""
_NEEDS = {"reconstruct": ("generate",), "train": ("reconstruct",), "evaluate": ("train",),
          "nrsfm": ("generate",)}
_TOP = {"campaign", "base", "grid", "items", "reconstruct", "train", "nrsfm"}
_CAMPAIGN = {"name", "stages", "chunk_frames", "retries"}
_STAGE_KEYS = {"reconstruct": {"normalisation": str, "mesh": str},
               "train": {"modes": int, "test_frames": int},
               "nrsfm": {"view": str, "k": int, "method": str}}
_MAX_ITEMS = 100_000


class PlanError(LipgenError, ValueError):
    """A campaign plan that cannot run: unknown key, impossible value, empty grid, ..."""


@dataclass(frozen=True)
class CampaignItem:
    """One dataset of the campaign: its settings and the swept values that made it."""

    index: int
    settings: GenerateSettings
    swept: dict

    @property
    def name(self) -> str:
        return f"{self.index:04d}"


@dataclass(frozen=True)
class CampaignPlan:
    """A checked plan. ``items`` in a fixed order; ``stages`` in pipeline order."""

    items: tuple[CampaignItem, ...]
    stages: tuple[str, ...] = STAGES
    chunk_frames: int = 16
    retries: int = 2
    name: str = "campaign"
    reconstruct: dict = field(default_factory=dict)
    train: dict = field(default_factory=dict)
    nrsfm: dict = field(default_factory=dict)
    swept_keys: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        """JSON form (what the campaign index stores; :func:`parse_plan` reads it back)."""
        return {"campaign": {"name": self.name, "stages": list(self.stages),
                             "chunk_frames": self.chunk_frames, "retries": self.retries},
                "items": [it.settings.to_dict() for it in self.items],
                "reconstruct": self.reconstruct, "train": self.train, "nrsfm": self.nrsfm}

    def fingerprint(self) -> str:
        """A hash of everything that determines the outputs (a resumed campaign must match it)."""
        return hashlib.sha256(json.dumps(self.to_dict(), sort_keys=True).encode()).hexdigest()[:16]

    @property
    def total_frames(self) -> int:
        return sum(it.settings.frames + it.settings.calib_frames for it in self.items)


def _settings_keys() -> set[str]:
    return {f.name for f in fields(GenerateSettings)}


def _check_keys(table: dict, allowed: set[str], where: str) -> None:
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise PlanError(f"plan: unknown key(s) {unknown} in {where}; known keys: {sorted(allowed)}")


def _coerce(key: str, value):
    """TOML has no tuples; ``size`` may also be written ``"640x480"``."""
    if key == "size" and isinstance(value, str):
        try:
            w, h = (int(v) for v in value.lower().split("x"))
        except ValueError:
            raise PlanError(f"plan: size must look like 640x480 or [640, 480], got {value!r}") from None
        return (w, h)
    if key in ("size", "board") and isinstance(value, list):
        return tuple(value)
    return value


def _settings(d: dict, where: str) -> GenerateSettings:
    try:
        return GenerateSettings(**{k: _coerce(k, v) for k, v in d.items()})
    except (TypeError, ValueError) as exc:
        raise PlanError(f"plan: {where} has impossible settings {d}: {exc}") from exc


def _stage_table(raw: dict, name: str) -> dict:
    table = raw.get(name, {})
    if not isinstance(table, dict):
        raise PlanError(f"plan: [{name}] must be a table, got {type(table).__name__}")
    _check_keys(table, set(_STAGE_KEYS[name]), f"[{name}]")
    for key, typ in _STAGE_KEYS[name].items():
        if key in table and (isinstance(table[key], bool) or not isinstance(table[key], typ)):
            raise PlanError(f"plan: [{name}] {key} must be a {typ.__name__}, got {table[key]!r}")
    if name == "train" and not 1 <= table.get("modes", 10) <= 200:
        raise PlanError(f"plan: [train] modes must be in [1, 200], got {table['modes']}")
    if name == "nrsfm":
        if table.get("view", "real") not in ("real", "virtual"):
            raise PlanError(f"plan: [nrsfm] view must be 'real' or 'virtual', got {table['view']!r}")
        from lipgen.nrsfm import METHODS

        if table.get("method", "dai") not in METHODS:
            raise PlanError(f"plan: [nrsfm] method must be one of {sorted(METHODS)}, got {table['method']!r}")
    if name == "reconstruct":
        from lipgen.recon.normalize import METHODS

        if table.get("normalisation", "least-force") not in METHODS:
            raise PlanError(f"plan: [reconstruct] normalisation must be one of {sorted(METHODS)}, "
                            f"got {table['normalisation']!r}")
    return dict(table)


def _whole(table: dict, key: str, default: int, lo: int, hi: int) -> int:
    v = table.get(key, default)
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise PlanError(f"plan: [campaign] {key} must be a whole number in [{lo}, {hi}], got {v!r}")
    return v


def parse_plan(raw: dict) -> CampaignPlan:
    """Check a plan (the parsed TOML, or :meth:`CampaignPlan.to_dict`) and expand its items.

    Raises
    ------
    PlanError
        Naming the key: an unknown table or key, a value out of range, an empty grid or list,
        a key both swept and listed, a stage whose input stage is missing.
    """
    if not isinstance(raw, dict):
        raise PlanError(f"plan: expected a table of tables, got {type(raw).__name__}")
    _check_keys(raw, _TOP, "the plan's top level")
    camp = raw.get("campaign", {})
    if not isinstance(camp, dict):
        raise PlanError("plan: [campaign] must be a table")
    _check_keys(camp, _CAMPAIGN, "[campaign]")
    stages = camp.get("stages", list(STAGES))
    if not isinstance(stages, list) or not stages:
        raise PlanError(f"plan: [campaign] stages must be a non-empty list of {list(STAGES)}, got {stages!r}")
    bad = [s for s in stages if s not in STAGES]
    if bad:
        raise PlanError(f"plan: [campaign] stages: unknown stage(s) {bad}; known: {list(STAGES)}")
    for s in stages:
        missing = [n for n in _NEEDS.get(s, ()) if n not in stages]
        if missing:
            raise PlanError(f"plan: [campaign] stages: {s!r} needs {missing} in the stages too")
    stages = tuple(s for s in STAGES if s in stages)
    chunk_frames = _whole(camp, "chunk_frames", 16, 1, 100_000)
    retries = _whole(camp, "retries", 2, 0, 20)
    name = camp.get("name", "campaign")
    if not isinstance(name, str) or not name.strip():
        raise PlanError(f"plan: [campaign] name must be a non-empty string, got {name!r}")
    keys = _settings_keys()
    base = raw.get("base", {})
    grid = raw.get("grid", {})
    listed = raw.get("items", [{}])
    for label, table in (("[base]", base), ("[grid]", grid)):
        if not isinstance(table, dict):
            raise PlanError(f"plan: {label} must be a table, got {type(table).__name__}")
        _check_keys(table, keys, label)
    if not isinstance(listed, list) or not all(isinstance(t, dict) for t in listed):
        raise PlanError("plan: items must be an array of tables ([[items]])")
    if not listed:
        raise PlanError("plan: items is an empty list; give at least one [[items]] table or leave it out")
    for k, t in enumerate(listed):
        _check_keys(t, keys, f"[[items]] #{k}")
    for key, values in grid.items():
        if not isinstance(values, list):
            raise PlanError(f"plan: [grid] {key} must be a list of values, got {values!r}")
        if not values:
            raise PlanError(f"plan: [grid] {key} is an empty list, so the grid has no items")
    both = sorted({k for t in listed for k in t} & set(grid))
    if both:
        raise PlanError(f"plan: key(s) {both} are both in [grid] and in [[items]]; give each in one place")
    n = len(listed) * (_prod(len(v) for v in grid.values()))
    if n > _MAX_ITEMS:
        raise PlanError(f"plan: {n} items is more than {_MAX_ITEMS}; split the campaign")
    grid_keys = list(grid)
    varied = sorted({k for t in listed for k in t if len({json.dumps(u.get(k)) for u in listed}) > 1})
    swept_keys = tuple(dict.fromkeys([*grid_keys, *varied]))
    items = []
    for k, (entry, combo) in enumerate(itertools.product(listed, itertools.product(*grid.values()))):
        d = {**base, **entry, **dict(zip(grid_keys, combo, strict=True))}
        s = _settings(d, f"item {k} ({', '.join(f'{a}={b!r}' for a, b in d.items() if a in swept_keys)})")
        items.append(CampaignItem(k, s, {key: _jsonable(getattr(s, key)) for key in swept_keys}))
    train = _stage_table(raw, "train")
    if "train" in stages:
        _check_training(items, train)
    return CampaignPlan(items=tuple(items), stages=stages,
                        chunk_frames=chunk_frames, retries=retries, name=name,
                        reconstruct=_stage_table(raw, "reconstruct"), train=train,
                        nrsfm=_stage_table(raw, "nrsfm"), swept_keys=swept_keys)


def _check_training(items: list[CampaignItem], train: dict) -> None:
    """Each item must leave enough training frames for the modes (the last frames are held out)."""
    from lipgen.evaluate.scoring import default_test_frames

    modes = train.get("modes", 10)
    for it in items:
        F = it.settings.frames
        T = train.get("test_frames") or default_test_frames(F)
        if not 1 <= T < F:
            raise PlanError(f"plan: [train] test_frames must be in [1, {F - 1}] for item {it.index} of {F} "
                            f"frames, got {T}")
        if F - T < modes + 1:
            raise PlanError(f"plan: [train] modes = {modes} needs at least {modes + 1} training frames, "
                            f"but item {it.index} has frames = {F} of which the last {T} are held out; "
                            "raise frames or lower modes")


def _prod(xs) -> int:
    out = 1
    for x in xs:
        out *= x
    return out


def _jsonable(v):
    return list(v) if isinstance(v, tuple) else v


def load_plan(path) -> CampaignPlan:
    """Read and check a TOML plan file (see the module docstring)."""
    p = Path(path)
    if not p.is_file():
        raise PlanError(f"plan file {p} does not exist")
    try:
        raw = tomllib.loads(p.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise PlanError(f"plan file {p} is not valid TOML: {exc}") from exc
    return parse_plan(raw)
